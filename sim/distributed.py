"""The swarm on the simulated network: a world and its agents, each its protocol machine, under a
fault schedule, checked as it runs.

This module plays the part that Zenoh, the kernel, the disk and the launcher play for real:
it carries every effect of a protocol (``machines.effects``) to where it goes, over
``sim.network``'s links: observations and control to the agents, intents to the world, an
agent's asks to its neighbours as queries and their replies back, liveliness tokens to everyone
who subscribes (with the tokens already there, as Zenoh's history gives them). It writes the
world's rows to a simulated ``episodes.csv`` and the agents' checkpoints to real files (of the
agents a schedule may crash; of all with ``checkpoint_all``), restarts a crashed agent from its
checkpoint through ``agent.restore`` as an agent process does, and a crashed world as
``--resume`` does, after the last complete row. The launcher's rule holds: once the world has
said the run is over, no agent is restarted (the launcher stops whatever still runs when the
world exits). Where a schedule kills every process at once, every file a run writes goes to
disk (``config.json``, ``episodes.csv``, every checkpoint, the world's shared table) and the run
is continued as ``launch/swarm.py --resume`` continues it, through the same functions
(``supervision.resume``): from the cut of its files, rows past it dropped.
"""

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import msgspec

from nnql_swarm.agent import checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.machine import AgentMachine
from nnql_swarm.protocol import keys
from nnql_swarm.sim.agent_processes import START_SPREAD_S, AgentProcesses, Query
from nnql_swarm.sim.checks import Checker
from nnql_swarm.sim.faults import Faults
from nnql_swarm.sim.network import Network, Process
from nnql_swarm.sim.schedule import Fault, Schedule, schedule_rng
from nnql_swarm.sim.world_process import WorldProcess
from nnql_swarm.storage.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.machine import WorldMachine

VIRTUAL_LIMIT_S = 3600.0
"""A run still going after this much virtual time did not end."""

EVENT_LIMIT = 2_000_000
"""A run still going after this many events did not end."""


@dataclass
class Outcome:
    """What one simulated run gave: its failures (none: it passed), its size, a digest of its
    history (the same seed gives the same digest), the metrics rows and, if asked for, the
    agents' final tables (``checkpoint.fingerprint``)."""

    seed: int
    failures: list[str]
    ticks: int
    events: int
    virtual_s: float
    digest: str
    rows: list[dict]
    fingerprints: list[str] | None = None
    fired: tuple[str, ...] = ()  # the kinds of the faults that hit, in order


class SimSwarm(WorldProcess, AgentProcesses, Faults):
    """One run of a :class:`~sim.schedule.Schedule` (see the module docstring): its state, and
    the run; the world's process (``sim.world_process``), the agents' (``sim.agent_processes``)
    and the faults (``sim.faults``) act on that state."""

    def __init__(self, schedule: Schedule, disk: Path | None = None,
                 checkpoint_all: bool = False, write_metrics: bool = False) -> None:
        """``disk``: where checkpoints (and, with ``write_metrics``, ``episodes.csv``) go; it
        is needed when the schedule crashes an agent or ``checkpoint_all`` is set."""
        self.schedule = schedule
        c = self.config = schedule.config
        self.n = n = c.n_agents
        self.net = Network(schedule_rng(schedule.seed, 1), schedule.latency)
        self.world = Process("world")
        self.agents = [Process(f"agent-{i}") for i in range(n)]
        self.processes = {p.name: p for p in (self.world, *self.agents)}
        self.world_protocol: WorldMachine | None = None
        self.protocols: list[AgentMachine | None] = [None] * n
        self.final_brains: list[AgentBrain | None] = [None] * n
        self.era = -1
        self.rows: list[dict] = []
        self.resumable = schedule.kills_all  # every file written, for --resume
        checkpoint_all = checkpoint_all or self.resumable
        self.checkpointed = frozenset(range(n)) if checkpoint_all else schedule.crashing_agents
        self.saving = set(self.checkpointed)  # whose checkpoints someone may still read
        self.keep_all = checkpoint_all
        if (self.checkpointed or self.resumable) and disk is None:
            raise ValueError("a schedule that checkpoints needs a disk")
        self.disk = None if disk is None else Path(disk)
        self.checkpoint_dir = None if disk is None else Path(disk) / CHECKPOINT_DIR
        self.write_metrics = write_metrics or self.resumable
        if self.resumable:
            (self.disk / CONFIG_FILE).write_text(c.to_json() + "\n")
        self.writer = EpisodeWriter(self.disk / EPISODES_FILE, sync=False) \
            if self.write_metrics else None
        self.saved: list[tuple[int, str] | None] = [None] * n
        self.saved_at: list[dict[int, str]] = [{} for _ in range(n)]  # episode -> tables
        self.generation = 0  # how often everyone was killed: restarts of earlier ones lapse
        self.received: dict[int, Query] = {}  # a query as its target numbered it -> the ask
        self.next_query = 0
        self.checker = Checker(c)
        self.alive_keys = [keys.alive_key(c.run_id, keys.ROLE_AGENT, i) for i in range(n)]
        self.intent_keys = [keys.intent_key(c.run_id, i) for i in range(n)]
        self.world_done = False
        self.completed = False
        self.run_over = False  # the world has said so: the launcher restarts nobody any more
        self.triggers: dict[int, list[Fault]] = {}
        for fault in schedule.faults:
            self.triggers.setdefault(fault.tick, []).append(fault)
        self.opened: set[int] = set()
        self.fired: list[str] = []
        self.forging: dict[int, int] = {}  # a compromised agent -> the incarnation that forges

    # The run.

    def run(self, fingerprints: bool = False) -> Outcome:
        net = self.net
        self._start_world(0, 0)
        for i in range(self.n):
            net.at(START_SPREAD_S * net.rng.random(), self._start_agent, i, False)
        ended = net.run(VIRTUAL_LIMIT_S, EVENT_LIMIT)
        check = self.checker
        if not ended:
            check.fail(f"the run did not end: {net.events} events, {net.now:.1f} virtual s")
        elif not self.completed:
            check.fail("the world did not complete the run"
                       + ("" if self.world_protocol is None
                          else f" (stuck at tick {self.world_protocol.world.tick})"))
        still = [i for i, a in enumerate(self.agents) if a.alive]
        if still:
            check.fail(f"agents {still} never stopped")
        check.metrics(self.rows, self.config.episodes)
        if self.writer is not None:
            self.writer.close()
        digest = hashlib.sha1(repr((self.rows, net.events, net.now)).encode()).hexdigest()[:12]
        ticks = sum(row["steps"] + 1 for row in self.rows)
        prints = None
        if fingerprints:
            prints = [None if b is None else checkpoint.fingerprint(b) for b in self.final_brains]
        return Outcome(self.schedule.seed, check.failures, ticks, net.events, net.now, digest,
                       self.rows, prints, tuple(self.fired))

    def _all_gone(self) -> None:
        if self.world_done and not any(a.alive for a in self.agents):
            self.net.halted = True


def run_schedule(schedule: Schedule, scratch: Path | None = None,
                 fingerprints: bool = False) -> Outcome:
    """Run one schedule; ``scratch``: a directory under which the files of a run that crashes
    an agent or kills everyone are kept while it runs (a fresh directory of their own, removed
    after)."""
    if not (schedule.crashing_agents or schedule.kills_all):
        return SimSwarm(schedule).run(fingerprints)
    with tempfile.TemporaryDirectory(prefix="nnql-sim-", dir=scratch) as disk:
        return SimSwarm(schedule, Path(disk)).run(fingerprints)
