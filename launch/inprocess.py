"""The swarm in one process: the very same world and agent logic, with function calls for Zenoh.

Agents decide in rank order, so every higher-ranked neighbour's intent is known when an agent
asks for it: exactly what the distributed negotiation gives when nobody misses a deadline. That
makes this runner the reference for the parity check (same config, same ``episodes.csv``).
"""

import time
from pathlib import Path
from typing import Callable

from agent import checkpoint
from agent.brain import AgentBrain
from protocol.config import SwarmConfig
from protocol.runfiles import CHECKPOINT_DIR, EPISODES_FILE
from world.engine import SwarmWorld, TickReport
from world.metrics import EpisodeWriter


def run_in_process(
    config: SwarmConfig,
    out_dir: Path,
    on_tick: Callable[[SwarmWorld, TickReport], None] | None = None,
    checkpoints: bool = True,
    on_episode_end: Callable[[AgentBrain, int], None] | None = None,
) -> SwarmWorld:
    """Run every episode of ``config``; writes ``episodes.csv`` (and checkpoints) to ``out_dir``."""
    out_dir = Path(out_dir)
    world = SwarmWorld(config)
    brains = [AgentBrain(i, config) for i in range(config.n_agents)]
    episode_start, episode_tick, slowest = time.perf_counter(), world.tick, 0.0
    with EpisodeWriter(out_dir / EPISODES_FILE) as writer:
        while not world.finished:
            tick_start = time.perf_counter()
            observations = world.observations()
            actions: dict[int, int] = {}
            for obs in sorted(observations, key=lambda o: o.rank):
                brain = brains[obs.agent]
                answers = {j: actions[j] for j in brain.neighbours_to_ask(obs)}
                actions[obs.agent] = brain.act(obs, answers)
                if obs.episode_end and checkpoints:
                    checkpoint.save(
                        checkpoint.checkpoint_path(out_dir / CHECKPOINT_DIR, obs.agent),
                        brain, obs.episode,
                    )
                if obs.episode_end and on_episode_end is not None:
                    on_episode_end(brain, obs.episode)
            report = world.apply([actions[i] for i in range(config.n_agents)])
            now = time.perf_counter()
            slowest = max(slowest, now - tick_start)
            if report.episode_row is not None:
                writer.write(report.episode_row, now - episode_start, world.tick - episode_tick,
                             slowest)
                episode_start, episode_tick, slowest = now, world.tick, 0.0
            if on_tick is not None:
                on_tick(world, report)
    return world
