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


class Subnets:
    """Several LANs on one machine: one bridge namespace per subnet (10.214.0.0/24, 10.215.0.0/24,
    ...), hosts that may sit on several of them (a router with a leg in each). Every address
    exists only inside these namespaces; `close` deletes them."""

    def __init__(self, layout):
        """layout: subnet name -> the roles on it, in address order (role i at .i+1)."""
        tag = f"sn{os.getpid() % 100000}"
        self.ns, self.addr, self.created = {}, {}, []
        try:
            for k, (subnet, roles) in enumerate(layout.items()):
                switch = f"{tag}-s{k}"
                ip("netns", "add", switch)
                self.created.append(switch)
                ip("-n", switch, "link", "add", "br0", "type", "bridge")
                ip("-n", switch, "link", "set", "br0", "up")
                for i, role in enumerate(roles):
                    ns = self.ns.get(role)
                    if ns is None:
                        ns = self.ns[role] = f"{tag}-{role}"
                        ip("netns", "add", ns)
                        self.created.append(ns)
                        ip("-n", ns, "link", "set", "lo", "up")
                    dev = f"eth{k}"
                    ip("-n", switch, "link", "add", f"p{i}", "type", "veth", "peer", "name", dev, "netns", ns)
                    ip("-n", switch, "link", "set", f"p{i}", "master", "br0", "up")
                    address = f"10.{214 + k}.0.{i + 1}"
                    ip("-n", ns, "addr", "add", f"{address}/24", "dev", dev)
                    ip("-n", ns, "link", "set", dev, "up")
                    self.addr[(role, subnet)] = address
        except BaseException:
            self.close()
            raise

    def popen(self, role, argv, **kw):
        return subprocess.Popen(["ip", "netns", "exec", self.ns[role], *argv], **kw)

    def close(self):
        for ns in reversed(self.created):
            ip("netns", "del", ns, check=False)
        self.created = []

    def links(self, role, up):
        """Takes every leg of a host down (a router PC losing power, seen from the wire) or up."""
        out = ip("-n", self.ns[role], "-o", "link", "show").stdout
        for line in out.splitlines():
            dev = line.split(":")[1].strip().split("@")[0]
            if dev.startswith("eth"):
                ip("-n", self.ns[role], "link", "set", dev, "up" if up else "down")
