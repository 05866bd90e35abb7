"""Fault schedules: a seed gives a small swarm run and the faults to inject into it, exactly.

A schedule is a run config (grid, learning preset, 2 or 3 episodes of 3 or 4 steps, swaps counted or
not; the run's seed is the schedule's) and a list of faults, each triggered when the world first
opens a given tick, some virtual time into it (at most one fault of each kind):

- ``drop``, ``duplicate``, ``reorder``: the network misbehaves for a while (``sim.network``);
- ``partition``: for a while no message crosses between ``group`` and the other processes;
- ``stall``: ``target`` (the world or an agent) stops answering for a while, as under SIGSTOP;
- ``crash``: ``target`` dies (kill -9) and its supervisor restarts it ``duration`` later: an
  agent from its last checkpoint, the world with ``--resume`` under the running agents;
- ``forge``: where the agents share a table, agent ``target`` is compromised: from then on, until
  it restarts, every learning record it sends is forged (``sim.forgery``). Drawn apart from the
  other kinds (:data:`FORGE_P`), after them, so that it leaves their draws alone.
- ``kill-all``: every process dies at once (kill -9 of the process group), and ``duration``
  later the run is continued with ``--resume``, from the cut its files give
  (``sim.resume``). Drawn from a stream of its own (one schedule in ten), so that it
  leaves the other draws alone.

Latency, duplicates and reordering alone cannot make anyone miss a deadline (they are far
shorter than the time-outs), nor can killing everyone at once, after which the run resumes as it
was: a schedule with no other fault is *benign*, and its run must equal the in-process run of its
config bit for bit.
"""

import random
from dataclasses import dataclass

from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.protocol.seeding import SIM_STREAM, stream_rng

KINDS = ("drop", "duplicate", "reorder", "partition", "stall", "crash")
BENIGN = frozenset({"duplicate", "reorder", "kill-all"})
KILL_ALL_SHARE = 0.1
"""The share of schedules that kill every process at once (and resume)."""
WINDOWS = ("drop", "duplicate", "reorder")
FORGE = "forge"
FORGE_P = 0.3
"""How often a schedule with faults, where the agents share a table, also has a forging agent."""
"""Faults that change the network's behaviour for a while."""

DEADLINE_S = 0.5
"""The tick deadline of a simulated run (virtual seconds; an agent's negotiation times out at
half of it)."""

SCHEDULED_PRESETS = ("path-nnql", "shield-nnql", "nnql", "best-nnql", "ql", "shield-ql", "daql",
                     "pibt-nnql")
PRESET_WEIGHTS = (12, 8, 16, 6, 3, 3, 2, 8)
"""The learning presets schedules run, and how often: the default (shared tables, the shield,
destination seeking on the known map) and the one before it (the same but the goal's offset),
the paper's the most, and priority inheritance over the agents' orders (a lost order is a stay:
nobody may collide for it); the oracle and n > 1 are the in-process simulator's only."""
GRIDS = ((11, 11), (11, 11), (11, 11), (16, 16), (24, 24), (30, 14))
"""Drawn uniformly: mostly the default grid, where everyone sees everyone and the negotiation is
one chain; sometimes larger ones, where agents see only some others and plan several asks."""


@dataclass(frozen=True)
class Fault:
    """One fault: ``kind`` at the world's first opening of ``tick``, ``offset_s`` into it, for
    ``duration_s`` (a crash: until the restart); ``target`` the process it hits (``"world"`` or
    ``"agent-<i>"``), ``group`` a partition's side, ``p`` a window's probability per message."""

    kind: str
    tick: int
    offset_s: float
    duration_s: float
    target: str = ""
    group: frozenset[str] = frozenset()
    p: float = 0.0

    def __str__(self) -> str:
        what = {"drop": f"p={self.p:.2f}", "duplicate": f"p={self.p:.2f}",
                "reorder": f"p={self.p:.2f}", "partition": "{" + ",".join(sorted(self.group)) + "}",
                "stall": self.target, "crash": self.target, "kill-all": "everyone",
                FORGE: self.target}[self.kind]
        return (f"{self.kind} {what} at tick {self.tick} +{self.offset_s * 1000:.2f} ms "
                f"for {self.duration_s * 1000:.1f} ms")


@dataclass(frozen=True)
class Schedule:
    """One seeded run: its config, the network's latency range and its faults."""

    seed: int
    config: SwarmConfig
    latency: tuple[float, float]
    faults: tuple[Fault, ...]

    @property
    def benign(self) -> bool:
        return all(f.kind in BENIGN for f in self.faults)

    @property
    def kills_all(self) -> bool:
        return any(f.kind == "kill-all" for f in self.faults)

    @property
    def crashing_agents(self) -> frozenset[int]:
        return frozenset(int(f.target.split("-")[1]) for f in self.faults
                         if f.kind == "crash" and f.target.startswith("agent-"))

    def describe(self) -> list[str]:
        c = self.config
        head = (f"seed {self.seed}: {c.n_agents} agents, {c.algo}, {c.width}x{c.height}, "
                f"{c.episodes} episodes of at most {c.max_steps} steps, swaps "
                f"{'count' if c.count_swaps else 'do not count'}, latency "
                f"{self.latency[0] * 1e6:.0f}-{self.latency[1] * 1e6:.0f} us")
        return [head] + [f"  {fault}" for fault in self.faults]


def schedule_rng(seed: int, index: int) -> random.Random:
    """A fast generator of one of a schedule's streams (0: the schedule, 1: the network, 2: the
    kill-all fault),
    seeded from the schedule's seed through ``protocol.seeding``."""
    return random.Random(int(stream_rng(seed, SIM_STREAM, index).integers(2**63)))


def draw_schedule(seed: int, agents: int = 8) -> Schedule:
    """The schedule of ``seed`` (the same seed, the same schedule)."""
    rng = schedule_rng(seed, 0)
    width, height = rng.choice(GRIDS)
    while 2 * agents > width * height:
        width, height = width + 5, height + 5
    preset = rng.choices(SCHEDULED_PRESETS, weights=PRESET_WEIGHTS)[0]
    episodes = rng.choices((2, 3), weights=(4, 1))[0]
    max_steps = rng.randint(3, 4)
    config = SwarmConfig(**PRESETS[preset], run_id=f"sim{seed}", n_agents=agents, episodes=episodes,
                         max_steps=max_steps, width=width, height=height, seed=seed % 2**31,
                         count_swaps=rng.random() < 0.5, tick_deadline_s=DEADLINE_S)
    low = rng.uniform(20e-6, 200e-6)
    latency = (low, low + rng.uniform(0.0, 800e-6))
    ticks = episodes * (max_steps + 1)
    names = ["world"] + [f"agent-{i}" for i in range(agents)]
    faults = []
    if rng.random() >= 0.1:
        kinds = rng.sample(KINDS, rng.randint(1, 4))
        for kind in kinds:
            tick = rng.randrange(ticks)
            offset = rng.uniform(0.0, 0.004)
            if kind in WINDOWS:
                p = rng.uniform(0.01, 0.3) if kind == "drop" else rng.uniform(0.05, 0.5)
                faults.append(Fault(kind, tick, offset, rng.uniform(0.002, 2.0), p=p))
            elif kind == "partition":
                side = frozenset(rng.sample(names, rng.randint(1, len(names) - 1)))
                faults.append(Fault(kind, tick, offset, rng.uniform(0.001, 1.5), group=side))
            elif kind == "stall":
                faults.append(Fault(kind, tick, offset, rng.uniform(0.001, 3.0),
                                    target=rng.choice(names)))
            else:
                target = "world" if rng.random() < 0.25 else f"agent-{rng.randrange(agents)}"
                faults.append(Fault(kind, tick, offset, rng.uniform(0.05, 3.0), target=target))
        if config.shared and rng.random() < FORGE_P:
            faults.append(Fault(FORGE, rng.randrange(ticks), rng.uniform(0.0, 0.004), 0.0,
                                target=f"agent-{rng.randrange(agents)}"))
    later = schedule_rng(seed, 2)
    if later.random() < KILL_ALL_SHARE:
        faults.append(Fault("kill-all", later.randrange(ticks), later.uniform(0.0, 0.004),
                            later.uniform(0.05, 3.0)))
    return Schedule(seed, config, latency, tuple(faults))
