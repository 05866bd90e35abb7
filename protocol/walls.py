"""The run's walls: static obstacles that every process derives from the run's config, never sent.

With ``--obstacle-density P`` a run's grid holds ``round(P * W * H)`` walls, drawn once for the
whole run from its own stream (``protocol.seeding.WALL_STREAM``), so the world, every agent and the
simulator know the same map without a message. Starts and goals are drawn only from the largest
4-connected region of free cells (:func:`open_cells`), so every goal can be reached; smaller pockets
stay empty. A run on a map (``--map``, ``world.terrain``) has the map's walls instead, which its
config carries.

A wall is a body that always stays: body ``n_agents + k`` is wall ``k`` (walls in cell order,
``y * W + x``). The rules treat it like an agent that stays (moving into it is a collision; a wall
earns and counts nothing), and a learner sees it as a neighbour whose next cell is known: its own
(the paper's scripted obstacles announce their next action; a wall's is always to stay).
"""

from collections import deque
from functools import lru_cache

import numpy as np

from nnql_swarm.protocol.seeding import WALL_STREAM, stream_rng

FREE, WALL = ".", "@"
"""A free cell and a wall in a map's rows (``SwarmConfig.map_rows``)."""

MAX_DENSITY = 0.4
"""The largest obstacle density: beyond it random walls split most grids into small pockets."""


def wall_count(width: int, height: int, density: float) -> int:
    """How many walls a grid holds at ``density``."""
    return int(round(density * width * height))


def map_walls(rows: tuple[str, ...]) -> np.ndarray:
    """A map's walls (``rows``) as ``(K, 2)`` cells ``(x, y)``, in cell order (``y * W + x``)."""
    cells = [(x, y) for y, row in enumerate(rows) for x, c in enumerate(row) if c != FREE]
    return np.array(cells, dtype=np.int64).reshape(-1, 2)


def wall_cells(seed: int, width: int, height: int, density: float) -> np.ndarray:
    """The run's walls as ``(K, 2)`` cells ``(x, y)``, in cell order (``y * W + x``)."""
    k = wall_count(width, height, density)
    if k == 0:
        return np.zeros((0, 2), dtype=np.int64)
    cells = np.sort(stream_rng(seed, WALL_STREAM, 0).choice(width * height, size=k, replace=False))
    return np.stack([cells % width, cells // width], axis=-1).astype(np.int64)


@lru_cache(maxsize=16)
def layout(seed: int, width: int, height: int, density: float,
           rows: tuple[str, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """A run's walls (its map's, ``rows``, if it has one, :func:`map_walls`; else
    :func:`wall_cells`) and the cells its starts and goals come from (:func:`open_cells`),
    computed once per process (both read-only)."""
    walls = map_walls(rows) if rows else wall_cells(seed, width, height, density)
    cells = open_cells(width, height, walls) if len(walls) else np.arange(width * height)
    walls.flags.writeable = cells.flags.writeable = False
    return walls, cells


def open_cells(width: int, height: int, walls: np.ndarray) -> np.ndarray:
    """The cells (``y * W + x``, ascending) of the largest 4-connected region without walls; of
    regions equally large, the one holding the lowest cell."""
    region = regions(width, height, walls)
    if not (region >= 0).any():
        return np.zeros(0, dtype=np.int64)
    sizes = np.bincount(region[region >= 0])
    return np.flatnonzero(region == int(np.argmax(sizes)))


def regions(width: int, height: int, walls: np.ndarray) -> np.ndarray:
    """Each cell's 4-connected region without walls (``y * W + x``; -1 on a wall), numbered in
    the order of their lowest cells."""
    free = np.ones(width * height, dtype=bool)
    free[walls[:, 1] * width + walls[:, 0]] = False
    region = np.full(width * height, -1, dtype=np.int64)
    label = 0
    for start in np.flatnonzero(free).tolist():
        if region[start] >= 0:
            continue
        region[start], todo = label, deque([start])
        while todo:
            cell = todo.popleft()
            x, y = cell % width, cell // width
            for nxt, ok in ((cell - 1, x > 0), (cell + 1, x < width - 1),
                            (cell - width, y > 0), (cell + width, y < height - 1)):
                if ok and free[nxt] and region[nxt] < 0:
                    region[nxt] = label
                    todo.append(nxt)
        label += 1
    return region


def path_lengths(width: int, height: int, walls: np.ndarray, starts: np.ndarray,
                 goals: np.ndarray) -> np.ndarray:
    """Each body's shortest path from its start to its goal around the walls (other bodies
    ignored): the Manhattan distance where there are none. Starts and goals lie in one region."""
    manhattan = np.abs(starts - goals).sum(axis=1)
    if len(walls) == 0 or len(goals) == 0:
        return manhattan
    free = np.ones((height, width), dtype=bool)
    free[walls[:, 1], walls[:, 0]] = False
    n, bodies = len(goals), np.arange(len(goals))
    reached = np.zeros((n, height, width), dtype=bool)
    reached[bodies, goals[:, 1], goals[:, 0]] = True
    lengths = np.full(n, -1, dtype=np.int64)
    steps = 0
    while True:
        now = reached[bodies, starts[:, 1], starts[:, 0]] & (lengths < 0)
        lengths[now] = steps
        if (lengths >= 0).all():
            return lengths
        grown = reached.copy()
        grown[:, 1:, :] |= reached[:, :-1, :]
        grown[:, :-1, :] |= reached[:, 1:, :]
        grown[:, :, 1:] |= reached[:, :, :-1]
        grown[:, :, :-1] |= reached[:, :, 1:]
        grown &= free
        if np.array_equal(grown, reached):
            raise ValueError("a goal cannot be reached from its start")
        reached, steps = grown, steps + 1
