"""A LAN on one machine: network namespaces ("hosts") joined by a bridge that lives in a
namespace of its own. Every address exists only inside these namespaces; `close` deletes
them, which removes their links and the bridge. Needs root (CI runs as root)."""

import os
import subprocess


def ip(*args, check=True):
    return subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30, check=check)


def can_create_namespaces():
    if os.geteuid() != 0:
        return "needs root (ip netns)"
    probe = f"ssprobe{os.getpid()}"
    r = ip("netns", "add", probe, check=False)
    if r.returncode != 0:
        return f"`ip netns add` fails: {r.stderr.strip()}"
    ip("netns", "del", probe, check=False)
    return None


class Lan:
    """Hosts named by role, on 10.213.0.0/24 (host i at .i+1), multicast allowed between them."""

    def __init__(self, roles, subnet="10.213.0"):
        tag = f"ss{os.getpid() % 100000}"
        self.switch = f"{tag}-sw"
        self.ns = {role: f"{tag}-{role}" for role in roles}
        self.addr = {role: f"{subnet}.{i + 1}" for i, role in enumerate(roles)}
        self.created = []
        try:
            self._create(subnet)
        except BaseException:
            self.close()
            raise

    def _create(self, subnet):
        ip("netns", "add", self.switch)
        self.created.append(self.switch)
        ip("-n", self.switch, "link", "add", "br0", "type", "bridge")
        # Forward multicast to every port (no IGMP querier here to make snooping useful).
        ip("-n", self.switch, "link", "set", "br0", "type", "bridge", "mcast_snooping", "0")
        ip("-n", self.switch, "link", "set", "br0", "up")
        for i, (role, ns) in enumerate(self.ns.items()):
            ip("netns", "add", ns)
            self.created.append(ns)
            port = f"p{i}"
            ip("-n", self.switch, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", ns)
            ip("-n", self.switch, "link", "set", port, "master", "br0", "up")
            ip("-n", ns, "addr", "add", f"{self.addr[role]}/24", "dev", "eth0")
            ip("-n", ns, "link", "set", "lo", "up")
            ip("-n", ns, "link", "set", "eth0", "up")
            # Multicast scouting (224.0.0.224) goes out of eth0, the only way off the host.
            ip("-n", ns, "route", "add", "224.0.0.0/4", "dev", "eth0")

    def popen(self, role, argv, **kw):
        """Runs argv on a host. `ip netns exec` execs it: the pid is the program's own."""
        return subprocess.Popen(["ip", "netns", "exec", self.ns[role], *argv], **kw)

    def link(self, role, up):
        """Takes a host's only link down or brings it back (its routes come back with it)."""
        ip("-n", self.ns[role], "link", "set", "eth0", "up" if up else "down")
        if up:
            ip("-n", self.ns[role], "route", "replace", "224.0.0.0/4", "dev", "eth0")

    def close(self):
        for ns in reversed(self.created):
            ip("netns", "del", ns, check=False)
        self.created = []
