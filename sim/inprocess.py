"""The swarm in one process: the swarm simulator (``sim.episode``) playing one run, with its files.

The simulator plays every agent and the world inside the compiled kernel, in rank order, exactly
as the distributed negotiation orders them when nobody misses a deadline; this runner adds what a
run leaves: ``episodes.csv`` (a row per episode, flushed as it ends), the agents' checkpoints at
the end (and the world's, where they share one table), and, if asked, every tick replayed to the
recording (``on_tick``) and every agent's tables at each episode's end (``on_episode_end``).
"""

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.world import world_checkpoint
from nnql_swarm.protocol.actions import STAY
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR, EPISODES_FILE
from nnql_swarm.sim.runs import Batch, Episodes, swarm_world
from nnql_swarm.sim.episode import (
    TR_ACTION, TR_ARRIVED, TR_COLLIDED, TR_GOAL_X, TR_GOAL_Y, TR_WANTED, TR_X, TR_Y,
)
from nnql_swarm.world.engine import TickReport
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.scenario import swarm_episode
from nnql_swarm.world.shared_table import SharedState


class TickView(NamedTuple):
    """The world as a tick left it, as the recording reads it (``recording.world.WorldViz``)."""

    cells: tuple[tuple[int, int], ...]
    arrived_flags: tuple[bool, ...]
    step: int


class SimulatedLearner:
    """One simulated agent's tables, as an agent process's learner shows them."""

    def __init__(self, batch: Batch, agent: int) -> None:
        self._batch, self._agent = batch, agent

    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        q_ds, q_ca = self._batch.tables(0, self._agent)
        return q_ds.copy(), q_ca.copy()

    @property
    def actions_taken(self) -> int:
        return self._batch.actions_taken(0, self._agent)

    def known_walls(self) -> list[int]:
        return self._batch.known_walls(0, self._agent)


@dataclass
class SimulatedAgent:
    """What checkpoints and the recording read of an agent: as an ``agent.brain.AgentBrain``."""

    agent: int
    config: SwarmConfig
    learner: SimulatedLearner
    rng: np.random.Generator


@dataclass
class InProcessRun:
    """What a finished in-process run reports."""

    episodes: Episodes
    violations: int


def run_in_process(
    config: SwarmConfig,
    out_dir: Path,
    on_tick: Callable[[TickView, TickReport], None] | None = None,
    checkpoints: bool = True,
    on_episode_end: Callable[[SimulatedAgent, int], None] | None = None,
    on_row: Callable[[dict], None] | None = None,
) -> InProcessRun:
    """Run every episode of ``config``; writes ``episodes.csv`` (and checkpoints) to ``out_dir``.
    ``on_row(row)`` follows each episode's row (its deterministic columns)."""
    out_dir = Path(out_dir)
    batch = Batch(swarm_world(config), [config], record=on_tick is not None)
    agents = [SimulatedAgent(i, config, SimulatedLearner(batch, i), batch.generator(0, i))
              for i in range(config.n_agents)]
    results = Episodes(1, config.episodes)
    rowed, playing = 0, False  # the episodes with a row; an episode half played
    try:
        with EpisodeWriter(out_dir / EPISODES_FILE, sync=False) as writer:
            for episode in range(config.episodes):
                started, first_tick = time.perf_counter(), int(batch.tick[0])
                playing = True
                batch.play(1, results)
                playing = False
                row = results.swarm_row(0, episode, config.n_agents)
                writer.write(row, time.perf_counter() - started, int(batch.tick[0]) - first_tick)
                rowed = episode + 1
                if on_tick is not None:
                    _replay(config, batch, row, on_tick)
                if on_episode_end is not None:
                    for agent in agents:
                        on_episode_end(agent, episode)
                if on_row is not None:
                    on_row(row)
    finally:
        # Stopped (Ctrl-C) in the middle of an episode, or before its row: the tables are no
        # episode's end with a row, so none is saved and a --resume plays the run afresh.
        if checkpoints and batch.episode and not playing and batch.episode == rowed:
            for agent in agents:
                agent_checkpoint.save(agent_checkpoint.checkpoint_path(out_dir / CHECKPOINT_DIR, agent.agent),
                                agent, batch.episode - 1)
            if config.shared:  # the world's copy, for a distributed --resume
                world_checkpoint.save(world_checkpoint.table_path(out_dir),
                                      SharedState(*agents[0].learner.tables()), batch.episode - 1,
                                      config)
    return InProcessRun(results, int(results.violations.sum()))


def _replay(config: SwarmConfig, batch: Batch, row: dict,
            on_tick: Callable[[TickView, TickReport], None]) -> None:
    """Hand the episode just played to ``on_tick``, tick by tick, from the simulator's trace
    (its agents: the walls after them never move)."""
    trace, steps = batch.trace[0][:, :config.n_agents], row["steps"]
    first = row["end_tick"] - steps
    for step in range(steps + 1):
        ending = step == steps
        if ending and row["episode"] + 1 < config.episodes:
            starts = swarm_episode(config.seed, row["episode"] + 1, config.width, config.height,
                                   config.n_agents, config.obstacle_density, config.map_rows,
                                   config.scenario).starts
            after = TickView(tuple(map(tuple, starts.tolist())), (False,) * config.n_agents, 0)
        else:
            later = trace[min(step + 1, steps)]
            after = TickView(tuple(zip(later[:, TR_X].tolist(), later[:, TR_Y].tolist())),
                             tuple(bool(a) for a in later[:, TR_ARRIVED]), step + 1)
        now = trace[step]
        actions = (STAY,) * config.n_agents if ending else tuple(now[:, TR_ACTION].tolist())
        collided = () if ending else tuple(np.flatnonzero(now[:, TR_COLLIDED]).tolist())
        wanted = tuple(now[:, TR_WANTED].tolist()) \
            if config.arbitration == "pibt" and not ending else ()
        goals: tuple = ()
        reached: tuple = ()
        if config.lifelong and not ending:
            later = trace[step + 1]
            goals = tuple(zip(later[:, TR_GOAL_X].tolist(), later[:, TR_GOAL_Y].tolist()))
            reached = tuple(np.flatnonzero((later[:, TR_GOAL_X] != now[:, TR_GOAL_X])
                                           | (later[:, TR_GOAL_Y] != now[:, TR_GOAL_Y])).tolist())
        on_tick(after, TickReport(first + step, row["episode"], not ending, actions, collided,
                                  (), (), row if ending else None, None, None, wanted, goals,
                                  reached))
