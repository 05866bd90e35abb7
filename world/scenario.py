"""Seeded scenario data: starts, goals and every scripted obstacle action, per episode.

Each episode draws from its own generator, derived from the run's seed and the episode number
(``protocol.seeding``), so an episode's data does not depend on
which algorithm runs it or on how many episodes came before: QL and nnQL see identical data.
"""

from dataclasses import dataclass

import numpy as np

from nnql_swarm.protocol.actions import N_ACTIONS
from nnql_swarm.protocol.seeding import SCENARIO_STREAM, stream_rng


def episode_rng(seed: int, episode: int) -> np.random.Generator:
    """The generator of one episode's scenario."""
    return stream_rng(seed, SCENARIO_STREAM, episode)


@dataclass(frozen=True)
class PaperEpisode:
    """One episode of the paper's experiment: one learner among scripted obstacles.

    ``starts[0]`` is the learner, ``starts[1:]`` the obstacles; ``obstacle_actions[t, j]`` is
    obstacle ``j``'s action at step ``t``.
    """

    starts: np.ndarray  # (1 + M, 2)
    goal: np.ndarray  # (2,)
    obstacle_actions: np.ndarray  # (max_steps, M)


def paper_episode(
    seed: int, episode: int, width: int, height: int, n_obstacles: int, max_steps: int
) -> PaperEpisode:
    """Draw distinct cells for the learner, its goal and the obstacles, and the obstacles' script."""
    rng = episode_rng(seed, episode)
    cells = rng.choice(width * height, size=n_obstacles + 2, replace=False)
    xy = np.stack([cells % width, cells // width], axis=-1).astype(np.int64)
    actions = rng.integers(0, N_ACTIONS, size=(max_steps, n_obstacles), dtype=np.int64)
    return PaperEpisode(starts=np.concatenate([xy[:1], xy[2:]]), goal=xy[1], obstacle_actions=actions)


@dataclass(frozen=True)
class SwarmEpisode:
    """One episode of a swarm run: every agent learns; starts and goals are all distinct cells."""

    starts: np.ndarray  # (N, 2)
    goals: np.ndarray  # (N, 2)


def swarm_episode(seed: int, episode: int, width: int, height: int, n_agents: int) -> SwarmEpisode:
    """Draw ``2 * n_agents`` distinct cells: the starts, then the goals."""
    if 2 * n_agents > width * height:
        raise ValueError(
            f"{n_agents} agents need {2 * n_agents} distinct start and goal cells; "
            f"a {width}x{height} grid has {width * height}"
        )
    rng = episode_rng(seed, episode)
    cells = rng.choice(width * height, size=2 * n_agents, replace=False)
    xy = np.stack([cells % width, cells // width], axis=-1).astype(np.int64)
    return SwarmEpisode(starts=xy[:n_agents], goals=xy[n_agents:])
