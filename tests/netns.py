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

Faults on one host's link (tests/test_netfaults.py, bench/netfaults.py): :meth:`Lan.netem` puts a
``tc netem`` qdisc (delay, jitter, loss, reordering) on both ends of the host's veth, so both
directions suffer it; :meth:`Lan.drop` drops a random share of the host's packets, in and out,
with iptables' ``statistic`` match; :meth:`Lan.partition` detaches the host's port from the bridge
(its own link stays up, its packets go nowhere) until :meth:`Lan.heal`. Each needs what the kernel
may lack: :func:`netem_unavailable_reason` and :func:`drop_unavailable_reason` say why not.
"""

import os
import secrets
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

PREFIX = "nnqlt"
NETDELAY = Path(__file__).resolve().parent / "netdelay.py"
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


def _probe_pair() -> tuple[str, str]:
    """Two throw-away namespaces joined by a veth (``e0`` in the first, up): see _unprobe.
    Raises RuntimeError, having deleted what it made, if they cannot be made."""
    first = f"{PREFIX}-{os.getpid()}-probe{secrets.token_hex(2)}"
    second = f"{first}x"
    try:
        _ip("netns", "add", first)
        _ip("netns", "add", second)
        _ip("link", "add", "e0", "netns", first, "type", "veth", "peer", "name", "e1", "netns",
            second)
        _ip("-n", first, "link", "set", "e0", "up")
    except RuntimeError:
        _unprobe(first, second)
        raise
    return first, second


def _unprobe(*namespaces: str) -> None:
    for namespace in namespaces:
        _ip("netns", "del", namespace, check=False)


def netem_unavailable_reason() -> str | None:
    """Why ``tc qdisc add ... netem`` cannot be used here (None if it can), tried on a veth."""
    reason = unavailable_reason()
    if reason is not None:
        return reason
    if shutil.which("tc") is None:
        return "the tc command (iproute2) is not installed"
    try:
        first, second = _probe_pair()
    except RuntimeError as error:
        return f"no veth between namespaces: {error}"
    try:
        added = subprocess.run(["ip", "netns", "exec", first, "tc", "qdisc", "add", "dev", "e0",
                                "root", "netem", "delay", "5ms", "2ms", "loss", "1%"],
                               capture_output=True, text=True, timeout=30)
        if added.returncode != 0:
            return (f"the kernel has no netem qdisc (sch_netem): tc qdisc add ... netem: "
                    f"{added.stderr.strip()}")
        return None
    finally:
        _unprobe(first, second)


def drop_unavailable_reason() -> str | None:
    """Why :meth:`Lan.drop` (iptables' statistic match) cannot be used here (None if it can)."""
    reason = unavailable_reason()
    if reason is not None:
        return reason
    if shutil.which("iptables") is None:
        return "the iptables command is not installed"
    try:
        first, second = _probe_pair()
    except RuntimeError as error:
        return f"no veth between namespaces: {error}"
    try:
        added = subprocess.run(["ip", "netns", "exec", first, *_drop_rule("-A", "INPUT", 0.02)],
                               capture_output=True, text=True, timeout=30)
        if added.returncode != 0:
            return f"iptables cannot drop at random here: {added.stderr.strip()}"
        return None
    finally:
        _unprobe(first, second)


def _drop_rule(action: str, chain: str, probability: float) -> list[str]:
    return ["iptables", "-w", action, chain, "-m", "statistic", "--mode", "random",
            "--probability", f"{probability:g}", "-j", "DROP"]


def _queue_rules(action: str) -> list[list[str]]:
    return [["iptables", "-w", action, chain, direction, "eth0", "-j", "NFQUEUE", "--queue-num",
             "0", "--queue-bypass"] for chain, direction in (("INPUT", "-i"), ("OUTPUT", "-o"))]


def delay_unavailable_reason() -> str | None:
    """Why :meth:`Lan.delay` (an NFQUEUE and tests/netdelay.py) cannot be used here."""
    reason = unavailable_reason()
    if reason is not None:
        return reason
    if shutil.which("iptables") is None:
        return "the iptables command is not installed"
    try:
        first, second = _probe_pair()
    except RuntimeError as error:
        return f"no veth between namespaces: {error}"
    try:
        for rule in _queue_rules("-A"):
            added = subprocess.run(["ip", "netns", "exec", first, *rule], capture_output=True,
                                   text=True, timeout=30)
            if added.returncode != 0:
                return f"iptables has no NFQUEUE target here: {added.stderr.strip()}"
        bound = subprocess.run(["ip", "netns", "exec", first, sys.executable, str(NETDELAY),
                                "--probe"], capture_output=True, text=True, timeout=30)
        if bound.returncode != 0 or bound.stdout.strip() != "ready":
            return f"tests/netdelay.py cannot bind an NFQUEUE: {bound.stderr.strip()[-300:]}"
        return None
    finally:
        _unprobe(first, second)


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    result = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and result.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {result.stderr.strip()}")
    return result


def _run(argv: list[str], check: bool = True) -> subprocess.CompletedProcess:
    result = subprocess.run(argv, capture_output=True, text=True, timeout=30)
    if check and result.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)}: {result.stderr.strip()}")
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

    # --- faults on one host's link ---

    def port(self, host: str) -> str:
        """The bridge port of ``host``'s veth, in the LAN's own namespace."""
        return f"p{self.hosts.index(host)}"

    def netem(self, host: str, *spec: str) -> None:
        """``tc netem`` with ``spec`` (e.g. ``delay 5ms 2ms loss 1%``) on both ends of ``host``'s
        link: what the host sends and what it receives suffers it. Replaces the one before."""
        for namespace, device in ((self.namespace(host), "eth0"),
                                  (f"{self.tag}-lan", self.port(host))):
            _run(["ip", "netns", "exec", namespace, "tc", "qdisc", "replace", "dev", device,
                  "root", "netem", *spec])

    def clear_netem(self, host: str) -> None:
        for namespace, device in ((self.namespace(host), "eth0"),
                                  (f"{self.tag}-lan", self.port(host))):
            _run(["ip", "netns", "exec", namespace, "tc", "qdisc", "del", "dev", device, "root"],
                 check=False)

    def drop(self, host: str, probability: float) -> None:
        """Drop each packet ``host`` sends or receives with ``probability`` (iptables)."""
        for chain in ("INPUT", "OUTPUT"):
            _run(self.command(host, _drop_rule("-A", chain, probability)))

    def delay(self, host: str, delay_ms: float, jitter_ms: float, reorder: float,
              seed: int = 0) -> subprocess.Popen:
        """Hold every packet of ``host``'s link, in and out, ``delay_ms ± jitter_ms`` (a
        ``reorder`` share not at all) in user space (tests/netdelay.py, for kernels without
        netem). Returns the delaying process, which the Lan stops on close; :meth:`clear_delay`
        stops it earlier."""
        delayer = self.popen(host, [sys.executable, str(NETDELAY), "--delay-ms", f"{delay_ms:g}",
                                    "--jitter-ms", f"{jitter_ms:g}", "--reorder", f"{reorder:g}",
                                    "--seed", str(seed)],
                             stdout=subprocess.PIPE, text=True)
        if delayer.stdout.readline().strip() != "ready":
            raise RuntimeError(f"tests/netdelay.py did not start in {host}")
        for rule in _queue_rules("-A"):
            _run(self.command(host, rule))
        return delayer

    def clear_delay(self, host: str, delayer: subprocess.Popen) -> str:
        """Stop delaying ``host``'s packets; returns the delayer's last words (``held N ...``)."""
        for rule in _queue_rules("-D"):
            _run(self.command(host, rule), check=False)
        delayer.send_signal(signal.SIGTERM)
        try:
            said = delayer.communicate(timeout=10)[0]
        except subprocess.TimeoutExpired:
            delayer.kill()
            said = delayer.communicate()[0]
        return said.strip()

    def dropped(self, host: str) -> int:
        """Packets :meth:`drop` has dropped at ``host`` so far (iptables' counters)."""
        listing = _run(self.command(host, ["iptables", "-w", "-L", "-n", "-v", "-x"])).stdout
        return sum(int(line.split()[0]) for line in listing.splitlines()
                   if "statistic mode random" in line)

    def clear_drop(self, host: str, probability: float) -> None:
        for chain in ("INPUT", "OUTPUT"):
            _run(self.command(host, _drop_rule("-D", chain, probability)), check=False)

    def partition(self, host: str) -> None:
        """Cut ``host`` off: its port leaves the bridge, so every packet to or from it is lost
        (its own link stays up, as behind a switch that lost its uplink)."""
        _ip("-n", f"{self.tag}-lan", "link", "set", self.port(host), "nomaster")

    def heal(self, host: str) -> None:
        """Undo :meth:`partition`."""
        _ip("-n", f"{self.tag}-lan", "link", "set", self.port(host), "master", "br0")

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
