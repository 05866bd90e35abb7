"""Walls (``--obstacle-density``): the map drawn from the seed, starts and goals in one region,
shortest paths around the walls, and a wall in the world: a body that stays and counts nothing."""

import subprocess
import sys
from collections import deque

import numpy as np
import pytest

from nnql_swarm.protocol.actions import RIGHT, STAY
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.seeding import SCENARIO_STREAM, stream_rng
from nnql_swarm.protocol.walls import open_cells, path_lengths, wall_cells
from nnql_swarm.world.engine import SwarmWorld
from nnql_swarm.world.scenario import swarm_episode
from tests.swarm_helpers import ROOT


def bfs(width, height, walls, start, goal):
    """The reference: a plain breadth-first search, one cell at a time."""
    blocked = {tuple(c) for c in walls}
    seen, todo = {tuple(start): 0}, deque([tuple(start)])
    while todo:
        x, y = todo.popleft()
        if (x, y) == tuple(goal):
            return seen[(x, y)]
        for nx, ny in ((x + 1, y), (x - 1, y), (x, y + 1), (x, y - 1)):
            if 0 <= nx < width and 0 <= ny < height and (nx, ny) not in blocked \
                    and (nx, ny) not in seen:
                seen[(nx, ny)] = seen[(x, y)] + 1
                todo.append((nx, ny))
    return None


def test_the_map_is_the_seeds_and_holds_the_density():
    a, again, other = (wall_cells(s, 32, 20, 0.2) for s in (7, 7, 8))
    assert len(a) == round(0.2 * 32 * 20) and np.array_equal(a, again)
    assert not np.array_equal(a, other)
    order = a[:, 1] * 32 + a[:, 0]
    assert (np.diff(order) > 0).all(), "walls in cell order, each once"
    assert len(wall_cells(7, 32, 20, 0.0)) == 0


@pytest.mark.parametrize("seed", range(6))
def test_starts_and_goals_lie_in_one_region_and_every_path_goes_around_the_walls(seed):
    width, height, n = 24, 18, 20
    config = SwarmConfig(n_agents=n, width=width, height=height, seed=seed, obstacle_density=0.3)
    walls, region = config.walls(), set(config.open_cells().tolist())
    assert not region & {y * width + x for x, y in walls.tolist()}
    cell = next(iter(region))  # the region is connected, and nothing bigger is free
    reachable = {c for c in region if bfs(width, height, walls, (cell % width, cell // width),
                                          (c % width, c // width)) is not None}
    assert reachable == region
    for episode in range(3):
        sc = swarm_episode(seed, episode, width, height, n, 0.3)
        drawn = (sc.starts[:, 1] * width + sc.starts[:, 0]).tolist() + \
            (sc.goals[:, 1] * width + sc.goals[:, 0]).tolist()
        assert len(set(drawn)) == 2 * n and set(drawn) <= region
        assert sc.shortest.tolist() == [bfs(width, height, walls, s, g)
                                        for s, g in zip(sc.starts, sc.goals)]


def test_a_wall_with_one_gap_makes_the_way_round():
    walls = np.array([[2, y] for y in range(4)], dtype=np.int64)  # column x = 2, gap at y = 4
    starts, goals = np.array([[0, 0], [4, 4]]), np.array([[4, 0], [4, 3]])
    assert path_lengths(5, 5, walls, starts, goals).tolist() == [12, 1]
    assert path_lengths(5, 5, walls[:0], starts, goals).tolist() == [4, 1]
    assert open_cells(3, 1, np.array([[1, 0]])).tolist() == [0], "of equal regions, the first"


def test_without_walls_the_scenario_is_drawn_as_it_always_was():
    for episode in range(5):
        sc = swarm_episode(3, episode, 11, 11, 8)
        cells = stream_rng(3, SCENARIO_STREAM, episode).choice(121, size=16, replace=False)
        assert (sc.starts[:, 1] * 11 + sc.starts[:, 0]).tolist() == cells[:8].tolist()
        assert (sc.goals[:, 1] * 11 + sc.goals[:, 0]).tolist() == cells[8:].tolist()
        assert sc.shortest.tolist() == np.abs(sc.starts - sc.goals).sum(axis=1).tolist()


def test_moving_into_a_wall_is_a_collision_of_the_agent_alone():
    config = SwarmConfig(n_agents=4, width=10, height=10, seed=1, obstacle_density=0.3)
    world = SwarmWorld(config)
    walls = {tuple(cell) for cell in config.walls().tolist()}
    starts = [tuple(cell) for cell in world.cells]
    into_wall = [i for i, (x, y) in enumerate(starts) if (x + 1, y) in walls]
    assert into_wall, "seed 1 puts an agent left of a wall"
    actions = [RIGHT if i in into_wall else STAY for i in range(4)]
    report = world.apply(actions)
    assert set(report.collided) == set(into_wall) and world.cells == tuple(starts)
    assert len(world.cells) == len(world.arrived_flags) == 4
    assert world.episode_row()["collisions"] == len(into_wall)


def test_a_bad_density_is_a_one_line_usage_error(tmp_path):
    for density, message in (("0.5", "the obstacle density must be 0..0.4"),
                             ("x", "invalid float value")):
        result = subprocess.run(
            [sys.executable, str(ROOT / "launch" / "swarm.py"), "--obstacle-density", density,
             "--out", str(tmp_path / "r")], capture_output=True, text=True, timeout=60)
        assert result.returncode == 2 and message in result.stderr, result.stderr
        assert "Traceback" not in result.stderr
