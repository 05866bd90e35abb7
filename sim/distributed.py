"""The swarm on the simulated network: a world and its agents, each its protocol machine, under a
fault schedule, checked as it runs.

This module plays the part that Zenoh, the kernel, the disk and the launcher play for real:
it carries every effect of a protocol (``protocol.effects``) to where it goes, over
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
(``sim.resume``): from the cut of its files, rows past it dropped.
"""

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import msgspec

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.sim.agent_processes import START_SPREAD_S, AgentProcesses
from nnql_swarm.sim.faults import Faults
from nnql_swarm.sim.schedule import Schedule
from nnql_swarm.sim.world_process import WorldProcess

VIRTUAL_LIMIT_S = 3600.0
"""A run still going after this much virtual time did not end."""

EVENT_LIMIT = 2_000_000
"""A run still going after this many events did not end."""


@dataclass
class Outcome:
    """What one simulated run gave: its failures (none: it passed), its size, a digest of its
    history (the same seed gives the same digest), the metrics rows and, if asked for, the
    agents' final tables (``agent_checkpoint.fingerprint``)."""

    seed: int
    failures: list[str]
    ticks: int
    events: int
    virtual_s: float
    digest: str
    rows: list[dict]
    fingerprints: list[str | None] | None = None  # None in it: an agent without final tables
    fired: tuple[str, ...] = ()  # the kinds of the faults that hit, in order


class SimSwarm(WorldProcess, AgentProcesses, Faults):
    """One run of a :class:`~sim.schedule.Schedule` (see the module docstring): its state
    (``sim.swarm_state``), and the run; the world's process (``sim.world_process``), the
    agents' (``sim.agent_processes``) and the faults (``sim.faults``) act on that state."""

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
                       f" (stuck at tick {self.world_protocol.world.tick})")
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
            prints = [None if b is None else agent_checkpoint.fingerprint(b) for b in self.final_brains]
        return Outcome(self.schedule.seed, check.failures, ticks, net.events, net.now, digest,
                       self.rows, prints, tuple(self.fired))


def run_schedule(schedule: Schedule, scratch: Path | None = None,
                 fingerprints: bool = False) -> Outcome:
    """Run one schedule; ``scratch``: a directory under which the files of a run that crashes
    an agent or kills everyone are kept while it runs (a fresh directory of their own, removed
    after)."""
    if not (schedule.crashing_agents or schedule.kills_all):
        return SimSwarm(schedule).run(fingerprints)
    with tempfile.TemporaryDirectory(prefix="nnql-sim-", dir=scratch) as disk:
        return SimSwarm(schedule, Path(disk)).run(fingerprints)
