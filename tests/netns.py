"""A throw-away LAN of network namespaces for multi-host tests: hosts on one bridge, nothing else.

    with Lan(["world", "a", "b"]) as lan:
        lan.popen("a", [sys.executable, "launch/swarm.py", ...])   # runs inside host "a"
        lan.ip("world")                                              # "10.213.7.1"

Every host is a namespace ``nnqlt-<pid>-<tag>-<host>`` with a loopback and an ``eth0`` veth whose
peer sits on a bridge in a namespace of its own (``...-lan``); the hosts get ``10.213.<n>.<i>/24``.
Nothing is connected to the machine's own network namespace, so no packet of a test leaves the
namespaces it created. Closing the Lan kills the processes it started (by pid), then any process
still inside its namespaces (which only it can have put there), then deletes the namespaces (their
veths and the bridge go with them). :func:`sweep_stale` removes what a killed test run left behind
(only namespaces with our prefix whose creating process is gone).
"""

import os
import secrets
import shutil
import signal
import subprocess
import time
from pathlib import Path

PREFIX = "nnqlt"
SUBNET = "10.213"


def unavailable_reason() -> str | None:
    """Why namespaces cannot be made here (None if they can)."""
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    if os.geteuid() != 0:
        return "network namespaces need root"
    probe = f"{PREFIX}-{os.getpid()}-probe{secrets.token_hex(2)}"
    made = subprocess.run(["ip", "netns", "add", probe], capture_output=True, text=True)
    if made.returncode != 0:
        return f"ip netns add failed: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", probe], capture_output=True)
    return None


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and result.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {result.stderr.strip()}")
    return result


def _namespaces() -> list[str]:
    listing = _ip("netns", "list", check=False).stdout
    return [line.split()[0] for line in listing.splitlines() if line.strip()]


def _kill_inside(namespace: str) -> None:
    """SIGKILL every process inside one of our namespaces (started there by us)."""
    pids = _ip("netns", "pids", namespace, check=False).stdout.split()
    for pid in pids:
        try:
            os.kill(int(pid), signal.SIGKILL)
        except (ProcessLookupError, ValueError):
            pass


def sweep_stale() -> None:
    """Delete namespaces left by earlier test runs that were killed (their creator pid is dead)."""
    for namespace in _namespaces():
        parts = namespace.split("-")
        if len(parts) < 3 or parts[0] != PREFIX or not parts[1].isdigit():
            continue
        if Path(f"/proc/{parts[1]}").exists():
            continue
        _kill_inside(namespace)
        _ip("netns", "del", namespace, check=False)


class Lan:
    """Hosts (network namespaces) on one private bridge; a context manager that cleans up."""

    def __init__(self, hosts: list[str], subnet: int | None = None) -> None:
        self.hosts = list(hosts)
        self.tag = f"{PREFIX}-{os.getpid()}-{secrets.token_hex(3)}"
        self.subnet = subnet if subnet is not None else 1 + secrets.randbelow(250)
        self.processes: list[subprocess.Popen] = []
        self.created: list[str] = []

    def namespace(self, host: str) -> str:
        return f"{self.tag}-{host}"

    def ip(self, host: str) -> str:
        return f"{SUBNET}.{self.subnet}.{self.hosts.index(host) + 1}"

    def __enter__(self) -> "Lan":
        sweep_stale()
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _add_namespace(self, name: str) -> str:
        _ip("netns", "add", name)
        self.created.append(name)
        _ip("-n", name, "link", "set", "lo", "up")
        return name

    def _build(self) -> None:
        lan = self._add_namespace(f"{self.tag}-lan")
        _ip("-n", lan, "link", "add", "br0", "type", "bridge")
        _ip("-n", lan, "link", "set", "br0", "up")
        for index, host in enumerate(self.hosts):
            ns = self._add_namespace(self.namespace(host))
            port = f"p{index}"
            # Both ends are created inside our namespaces: nothing ever appears in the host's.
            _ip("link", "add", "eth0", "netns", ns, "type", "veth",
                "peer", "name", port, "netns", lan)
            _ip("-n", lan, "link", "set", port, "master", "br0")
            _ip("-n", lan, "link", "set", port, "up")
            _ip("-n", ns, "addr", "add", f"{self.ip(host)}/24", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")
        self._wait_reachable()

    def _wait_reachable(self, timeout: float = 10.0) -> None:
        """Wait until the first host reaches every other (bridge ports take a moment to forward)."""
        first = self.hosts[0]
        for host in self.hosts[1:]:
            deadline = time.monotonic() + timeout
            while True:
                ping = subprocess.run(
                    ["ip", "netns", "exec", self.namespace(first), "ping", "-c", "1", "-W", "1",
                     self.ip(host)], capture_output=True)
                if ping.returncode == 0:
                    break
                if shutil.which("ping") is None or time.monotonic() > deadline:
                    return
                time.sleep(0.1)

    def command(self, host: str, argv: list[str]) -> list[str]:
        """``argv`` wrapped to run inside ``host``."""
        return ["ip", "netns", "exec", self.namespace(host), *argv]

    def popen(self, host: str, argv: list[str], **kwargs) -> subprocess.Popen:
        """Start ``argv`` inside ``host`` in a session of its own; the Lan kills it on close."""
        kwargs.setdefault("start_new_session", True)
        process = subprocess.Popen(self.command(host, argv), **kwargs)
        self.processes.append(process)
        return process

    def close(self) -> None:
        for process in self.processes:
            if process.poll() is None:
                try:
                    os.killpg(process.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + 3
        for process in self.processes:
            try:
                process.wait(max(0.05, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(process.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                process.wait(5)
        for name in reversed(self.created):
            _kill_inside(name)
        for name in reversed(self.created):
            _ip("netns", "del", name, check=False)
        self.created = []
