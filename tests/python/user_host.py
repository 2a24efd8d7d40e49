"""A machine of its own for commands typed as a user types them.

The docs' commands use the default config and port (peer mode, the rendezvous on
tcp/127.0.0.1:7447). So that they meet nothing else on the machine (another test, a loop a
developer left running) and nothing else meets them, each host is a network namespace of its
own with only loopback up: 7447 is free there, and multicast cannot leave it. Its working
directory looks like the checkout (config/, scenarios/, clients/ and target/ linked), `slipstream`
and the node binaries are on PATH as after `cargo install --path .`, and `python3` is the test
venv's (eclipse-zenoh installed). Commands are given as text and run by bash, exactly as
typed. Needs root (`ip netns`); CI runs as root.

Every process a host starts is stopped when the host closes, and `leftovers()` lists any
process still inside its namespace: "no process left behind" is checked with it.
"""

import os
import pathlib
import signal
import subprocess
import sys
import time

from conftest import ROOT

# Linked into the host's working directory, so relative paths in the docs resolve.
CHECKOUT = ("config", "scenarios", "clients", "target")


def can_create():
    """None when hosts can be made here, else why not."""
    if os.geteuid() != 0:
        return "needs root (ip netns)"
    probe = f"ssdoc{os.getpid()}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"`ip netns add` fails: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


class Proc:
    """A command started on a host: its process, its output files and when things happened."""

    def __init__(self, command, popen, out, err):
        self.command, self.popen, self.out, self.err = command, popen, out, err
        self.started = time.monotonic()
        self.signalled = self.ended_at = self.code = None

    def signal(self, sig=signal.SIGINT):
        self.signalled = time.monotonic()
        if self.popen.poll() is None:
            self.popen.send_signal(sig)

    def wait(self, timeout):
        """The exit code; fails the test (killing the process) when it does not end in time."""
        try:
            self.code = self.popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.popen.kill()
            self.popen.wait(timeout=10)
            raise AssertionError(f"`{self.command}` did not end within {timeout} s; stderr:\n{self.stderr()[-3000:]}")
        self.ended_at = time.monotonic()
        return self.code

    @property
    def elapsed(self):
        return self.ended_at - self.started

    def since_signal(self):
        """Seconds from the signal to the exit (after `wait`)."""
        return self.ended_at - self.signalled

    def stdout(self):
        return self.out.read_text(errors="replace")

    def stderr(self):
        return self.err.read_text(errors="replace")


class UserHost:
    def __init__(self, tmp_path):
        self.ns = f"ssdoc{os.getpid() % 100000}-{id(self) % 10000}"
        subprocess.run(["ip", "netns", "add", self.ns], check=True, capture_output=True)
        subprocess.run(["ip", "-n", self.ns, "link", "set", "lo", "up"], check=True)
        self.dir = pathlib.Path(tmp_path) / "checkout"
        self.dir.mkdir(parents=True, exist_ok=True)
        for name in CHECKOUT:
            (self.dir / name).symlink_to(ROOT / name)
        self.home = pathlib.Path(tmp_path) / "home"
        self.home.mkdir(exist_ok=True)
        venv_bin = pathlib.Path(sys.executable).parent
        self.env = {k: v for k, v in os.environ.items() if not k.startswith(("RUST_LOG", "SLIPSTREAM_", "ZENOH_"))}
        self.env.update(PATH=f"{ROOT / 'target' / 'release'}:{venv_bin}:{os.environ['PATH']}", HOME=str(self.home),
                        NO_COLOR="1")
        self.procs = []
        self.count = 0

    def start(self, command, env=None):
        """Starts `command` (bash syntax, as typed) in the host's working directory."""
        self.count += 1
        out, err = self.dir / f".{self.count}.out", self.dir / f".{self.count}.err"
        popen = subprocess.Popen(["ip", "netns", "exec", self.ns, "bash", "-c", f"exec {command}"],
                                 cwd=self.dir, env={**self.env, **(env or {})}, stdin=subprocess.DEVNULL,
                                 stdout=out.open("wb"), stderr=err.open("wb"), start_new_session=True)
        proc = Proc(command, popen, out, err)
        self.procs.append(proc)
        return proc

    def run(self, command, timeout, env=None):
        """Runs `command` to its end; returns the Proc (`.code`, `.elapsed`)."""
        proc = self.start(command, env)
        proc.wait(timeout)
        return proc

    @staticmethod
    def finish(proc, timeout):
        """Waits for a started command that ends by itself; returns its exit code."""
        return proc.wait(timeout)

    @staticmethod
    def stop(proc, sig=signal.SIGINT, timeout=30):
        """Signals a started command and waits for it; returns its exit code."""
        proc.signal(sig)
        return proc.wait(timeout)

    def wait_for(self, proc, text, timeout, stream="stderr"):
        """Waits until `text` appears in the command's output (it must still run)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            seen = proc.stderr() if stream == "stderr" else proc.stdout()
            if text in seen:
                return seen
            assert proc.popen.poll() is None, f"`{proc.command}` ended ({proc.popen.returncode}):\n{proc.stderr()[-3000:]}"
            time.sleep(0.1)
        raise AssertionError(f"`{proc.command}` never printed {text!r}:\n{proc.stderr()[-3000:]}")

    def leftovers(self):
        """Processes still running inside the host, as (pid, command line)."""
        pids = subprocess.run(["ip", "netns", "pids", self.ns], capture_output=True, text=True).stdout.split()
        found = []
        for pid in pids:
            try:
                cmdline = pathlib.Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode().strip()
                state = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
            except OSError:
                continue
            if state != "Z":
                found.append((int(pid), cmdline))
        return found

    def close(self):
        for p in self.procs:
            if p.popen.poll() is None:
                try:
                    os.killpg(p.popen.pid, signal.SIGKILL)
                except OSError:
                    pass
                p.popen.wait(timeout=10)
        for pid, _ in self.leftovers():
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
        subprocess.run(["ip", "netns", "del", self.ns], capture_output=True)
