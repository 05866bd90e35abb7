"""A swarm across namespace hosts, through a router, with one fault on the real network mid-run.

The layout is docs/operations.md's recommended one (tests/test_multihost.py runs it clean): host
``world`` runs launch/router.py and the world, hosts ``a`` and ``b`` the two halves of the agents,
every process a client of the router. :func:`run` starts them, applies a :class:`Fault` once the
first episode has ended (or before the start, for a fault that lasts the whole run), and returns
what the run left (:class:`Outcome`). Used by tests/test_netfaults.py and bench/netfaults.py.

The faults (:data:`FAULTS`):

- ``netem``: ``tc netem`` on hosts a and b, both directions, the whole run: 5 ms delay with 2 ms
  jitter, 25 % of packets sent at once (the rest delayed, so they overtake each other), 1 % loss;
- ``delay``: the same delay, jitter and reordering without netem, for kernels that lack it: every
  packet of hosts a and b, in and out, held 5 ms ± 2 ms by tests/netdelay.py (user space, through
  an NFQUEUE), 25 % let through at once; no loss;
- ``loss``: 2 % of hosts a's and b's packets dropped, in and out, the whole run (iptables);
- ``partition-short``, ``partition-long``: host a cut off from the LAN for 1 s (half the tick
  deadline) or 5 s (two and a half deadlines), then back;
- ``router-restart``: the router killed (SIGKILL) and started again on the same endpoint 1 s
  later;
- ``partition-outlasting`` (not among :data:`DEFAULT_FAULTS`): host a cut off for 14 s, longer
  than Zenoh's lease (10 s), in a run that ends meanwhile. The world plays on without host a's
  agents and completes; they never hear it, and host a's launcher waits for it until stopped
  (docs/operations.md, "A partition longer than Zenoh's lease").
"""

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes
from tests import netns

ROOT = Path(__file__).resolve().parent.parent
PY = sys.executable
SWARM, ROUTER = str(ROOT / "launch" / "swarm.py"), str(ROOT / "launch" / "router.py")
HOSTS = ["world", "a", "b"]

NETEM = ("delay", "5ms", "2ms", "reorder", "25%", "50%", "loss", "1%")
DELAY_MS, JITTER_MS, REORDER = 5.0, 2.0, 0.25
LOSS = 0.02
SHORT_S, LONG_S, OUTLASTING_S = 1.0, 5.0, 14.0
ROUTER_DOWN_S = 1.0


@dataclass
class Fault:
    """What goes wrong: ``before`` (the whole run) or ``during`` (once episode 0 has ended)."""
    name: str
    what: str
    needs: str = "netns"
    """``netns``, ``netem``, ``delay`` or ``drop``: which of tests/netns.py's probes must pass."""
    before: Callable | None = None
    during: Callable | None = None
    after: Callable | None = None
    """Undoes ``before`` once the run's processes are stopped."""


def _netem(lan, ctx) -> None:
    for host in ("a", "b"):
        lan.netem(host, *NETEM)


def _clear_netem(lan, ctx) -> None:
    for host in ("a", "b"):
        lan.clear_netem(host)


def _delay(lan, ctx) -> None:
    for seed, host in enumerate(("a", "b")):
        ctx.delayers[host] = lan.delay(host, DELAY_MS, JITTER_MS, REORDER, seed=seed)


def _clear_delay(lan, ctx) -> None:
    for host, delayer in ctx.delayers.items():
        said = lan.clear_delay(host, delayer)
        ctx.held += int(said.split()[1]) if said.startswith("held ") else 0


def _loss(lan, ctx) -> None:
    for host in ("a", "b"):
        lan.drop(host, LOSS)


def _clear_loss(lan, ctx) -> None:
    ctx.dropped = sum(lan.dropped(host) for host in ("a", "b"))
    for host in ("a", "b"):
        lan.clear_drop(host, LOSS)


def _partition(seconds: float):
    def cut(lan, ctx) -> None:
        lan.partition("a")
        time.sleep(seconds)
        lan.heal("a")
    return cut


def _restart_router(lan, ctx) -> None:
    ctx.router.kill()
    time.sleep(ROUTER_DOWN_S)
    ctx.router = ctx.start_router()


FAULTS = {fault.name: fault for fault in (
    Fault("clean", "no fault"),
    Fault("netem", "netem on hosts a and b: delay 5 ms ± 2 ms, 25 % reordered, 1 % loss",
          needs="netem", before=_netem, after=_clear_netem),
    Fault("delay", "hosts a and b: packets held 5 ms ± 2 ms in user space, 25 % let through "
          "at once (tests/netdelay.py)", needs="delay", before=_delay, after=_clear_delay),
    Fault("loss", f"{LOSS:.0%} of hosts a's and b's packets dropped (iptables)", needs="drop",
          before=_loss, after=_clear_loss),
    Fault("partition-short", f"host a cut off for {SHORT_S:g} s", during=_partition(SHORT_S)),
    Fault("partition-long", f"host a cut off for {LONG_S:g} s", during=_partition(LONG_S)),
    Fault("router-restart", f"the router killed, started again {ROUTER_DOWN_S:g} s later",
          during=_restart_router),
    Fault("partition-outlasting", f"host a cut off for {OUTLASTING_S:g} s, past Zenoh's lease",
          during=_partition(OUTLASTING_S)),
)}
DEFAULT_FAULTS = [name for name in FAULTS if name != "partition-outlasting"]
"""The faults that every run survives whole (tests/test_netfaults.py checks each)."""


def unavailable(fault: Fault) -> str | None:
    """Why ``fault`` cannot be made on this machine (None if it can)."""
    return {"netns": netns.unavailable_reason, "netem": netns.netem_unavailable_reason,
            "delay": netns.delay_unavailable_reason,
            "drop": netns.drop_unavailable_reason}[fault.needs]()


@dataclass
class Outcome:
    world_code: int | None
    agent_codes: list
    rows: list[dict]
    world_out: Path
    agent_outs: list[Path]
    logs: dict[str, Path]
    fault_at_s: float | None = None
    """When the fault began, from the world's start (None: before the start, or never)."""
    rows_after_fault: int | None = None
    """Episodes written when the fault had ended (a fault during the run ends before the run)."""
    dropped: int | None = None
    """Packets the ``loss`` fault dropped."""
    held: int | None = None
    """Packets the ``delay`` fault handled (held or let through at once)."""
    fault_error: str | None = None
    wall_s: float = 0.0
    timed_out: list[str] = field(default_factory=list)

    def complete(self, episodes: int) -> bool:
        """Every launcher exited 0 and every episode was written once, in order."""
        return (self.world_code == 0 and self.agent_codes == [0, 0] and not self.timed_out
                and [int(row["episode"]) for row in self.rows] == list(range(episodes)))

    @property
    def missed(self) -> int:
        return sum(int(row["missed_intents"]) for row in self.rows)

    @property
    def ticks_per_s(self) -> float:
        """All ticks over all episodes' durations (start-up excluded), as bench/multihost.py."""
        ticks = sum(int(row["steps"]) + 1 for row in self.rows)
        seconds = sum(float(row["duration_s"]) for row in self.rows)
        return ticks / seconds if seconds else 0.0

    def deterministic(self) -> list[tuple]:
        return [tuple(row[f] for f in EPISODE_FIELDS) for row in self.rows]

    def log(self, name: str) -> str:
        path = self.logs.get(name)
        return path.read_text() if path and path.exists() else ""


class _Context:
    """What a fault may act on (the router, restartable on its endpoint) and what it leaves."""

    def __init__(self, lan: netns.Lan, endpoint: str, logs: Path) -> None:
        self.lan, self.endpoint, self.logs = lan, endpoint, logs
        self.starts = 0
        self.delayers: dict[str, subprocess.Popen] = {}
        self.held = 0
        self.dropped = 0
        self.router = self.start_router()

    def start_router(self) -> subprocess.Popen:
        self.starts += 1
        log = self.logs / f"router-{self.starts}.out"
        deadline = time.monotonic() + 30
        while True:
            with open(log, "w") as out, open(self.logs / f"router-{self.starts}.err", "w") as err:
                router = self.lan.popen("world", [PY, ROUTER, "--listen", self.endpoint],
                                        stdout=out, stderr=err)
            while router.poll() is None and "listening on" not in log.read_text():
                time.sleep(0.02)
            if router.poll() is None:
                return router
            if time.monotonic() > deadline:  # e.g. the port still held by the router before
                raise RuntimeError(f"the router did not start: "
                                   f"{(self.logs / f'router-{self.starts}.err').read_text()}")
            time.sleep(0.1)


def run(lan: netns.Lan, out: Path, fault: Fault, *, agents: int = 4, episodes: int = 6,
        max_steps: int = 30, seed: int = 3, port: int = 7447, timeout_s: float = 150,
        run_options: tuple[str, ...] = ()) -> Outcome:
    """One run of ``agents`` agents through the router with ``fault``; everything it started is
    stopped before it returns (the router too)."""
    out.mkdir(parents=True, exist_ok=True)
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    endpoint = f"tcp/{lan.ip('world')}:{port}"
    common = ["--agents", str(agents), "--episodes", str(episodes), "--max-steps", str(max_steps),
              "--seed", str(seed), "--run-id", "netfault", "--no-record", "--no-progress",
              "--mode", "client", "--connect", endpoint, *run_options]
    ctx = _Context(lan, endpoint, logs)
    if fault.before:
        fault.before(lan, ctx)
    env = {**os.environ, "NNQL_LOG": "WARNING"}
    started = []

    def launch(host: str, name: str, argv: list[str], where: Path) -> subprocess.Popen:
        with open(logs / f"{name}.out", "w") as o, open(logs / f"{name}.err", "w") as e:
            process = lan.popen(host, [PY, SWARM, *common, *argv, "--out", str(where)],
                                cwd=ROOT, stdout=o, stderr=e, env=env)
        started.append(process)
        return process

    half = agents // 2
    world_out = out / "world"
    agent_outs = [out / "a", out / "b"]
    begin = time.monotonic()
    world = launch("world", "world", ["--role", "world"], world_out)
    agent_processes = [
        launch("a", "agents-a", ["--role", "agents", "--agent-ids", f"0-{half - 1}"],
               agent_outs[0]),
        launch("b", "agents-b", ["--role", "agents", "--agent-ids", f"{half}-{agents - 1}"],
               agent_outs[1]),
    ]
    outcome = Outcome(None, [], [], world_out, agent_outs,
                      {"world": logs / "world.err", "a": logs / "agents-a.err",
                       "b": logs / "agents-b.err"})
    injector = None
    if fault.during:
        def inject() -> None:
            episodes_csv = world_out / "episodes.csv"
            while world.poll() is None:
                if episodes_csv.exists() and len(episodes_csv.read_text().splitlines()) >= 2:
                    outcome.fault_at_s = time.monotonic() - begin
                    try:
                        fault.during(lan, ctx)
                    except Exception as error:  # reported, and the test fails on it
                        outcome.fault_error = repr(error)
                    if world.poll() is None:
                        outcome.rows_after_fault = len(episodes_csv.read_text().splitlines()) - 1
                    return
                time.sleep(0.01)
        injector = threading.Thread(target=inject, daemon=True)
        injector.start()
    try:
        try:
            outcome.world_code = world.wait(timeout_s)
        except subprocess.TimeoutExpired:
            outcome.timed_out.append("world")
        if injector:
            injector.join(OUTLASTING_S + 10)
        for name, process in zip("ab", agent_processes):
            try:
                outcome.agent_codes.append(process.wait(30))
            except subprocess.TimeoutExpired:
                outcome.timed_out.append(f"agents-{name}")
                outcome.agent_codes.append(None)
        outcome.wall_s = time.monotonic() - begin
    finally:
        for process in [*started, ctx.router]:
            if process.poll() is None:
                try:
                    os.killpg(process.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
                try:
                    process.wait(5)
                except subprocess.TimeoutExpired:
                    os.killpg(process.pid, signal.SIGKILL)
                    process.wait(5)
        if fault.after:
            fault.after(lan, ctx)
            outcome.dropped, outcome.held = ctx.dropped, ctx.held
    if (world_out / "episodes.csv").exists():
        outcome.rows = read_episodes(world_out / "episodes.csv")
    return outcome
