"""Seeded scenario data: starts, goals and every scripted obstacle action, per episode.

Each episode draws from its own generator, derived from the run's seed and the episode number
(``protocol.seeding``), so an episode's data does not depend on
which algorithm runs it or on how many episodes came before: QL and nnQL see identical data.
Where the grid has walls (``protocol.walls``: one map for the whole run, drawn from the seed or
read from ``--map``), starts and goals come from its largest free region, and each agent's
shortest path goes around them; a scenario (``--scen``) gives the same starts and goals every
episode instead.
"""

from dataclasses import dataclass

import numpy as np

from nnql_swarm.protocol.actions import N_ACTIONS
from nnql_swarm.protocol.seeding import SCENARIO_STREAM, stream_rng
from nnql_swarm.protocol.walls import layout, path_lengths


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
    """One episode of a swarm run: every agent learns; starts and goals are all distinct cells,
    and ``shortest[i]`` is agent ``i``'s shortest path (around the walls, if any)."""

    starts: np.ndarray  # (N, 2)
    goals: np.ndarray  # (N, 2)
    shortest: np.ndarray  # (N,)


def swarm_episode(seed: int, episode: int, width: int, height: int, n_agents: int,
                  obstacle_density: float = 0.0, rows: tuple[str, ...] = (),
                  tasks: tuple = ()) -> SwarmEpisode:
    """Draw ``2 * n_agents`` distinct free cells: the starts, then the goals; on the map
    ``rows`` if given (``world.terrain``), and with ``tasks`` (a scenario's ``(start_x, start_y,
    goal_x, goal_y)`` per agent) those starts and goals in every episode."""
    walls, free = layout(seed, width, height, obstacle_density, rows)
    if tasks:
        xy = np.array(tasks[:n_agents], dtype=np.int64).reshape(-1, 4)
        starts, goals = xy[:, :2].copy(), xy[:, 2:].copy()
        return SwarmEpisode(starts=starts, goals=goals,
                            shortest=path_lengths(width, height, walls, starts, goals))
    if 2 * n_agents > len(free):
        raise ValueError(
            f"{n_agents} agents need {2 * n_agents} distinct start and goal cells; "
            f"a {width}x{height} grid has {len(free)} free"
        )
    rng = episode_rng(seed, episode)
    if len(walls):
        cells = rng.choice(free, size=2 * n_agents, replace=False)
    else:  # without walls: any cell of the grid
        cells = rng.choice(width * height, size=2 * n_agents, replace=False)
    xy = np.stack([cells % width, cells // width], axis=-1).astype(np.int64)
    starts, goals = xy[:n_agents], xy[n_agents:]
    return SwarmEpisode(starts=starts, goals=goals,
                        shortest=path_lengths(width, height, walls, starts, goals))
