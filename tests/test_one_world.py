"""The one-world rules and world against the batch rules they stand in for, bit for bit.

``world.rules`` has plain-Python twins of its batch functions for the single world of a swarm
run, and ``SwarmWorld`` plays its ticks by them; ``tests/batch_world.py`` is the same world on
the batch rules. Every result must be identical: cells, collisions, every float's bits, every
observation, report and episode row.
"""

import numpy as np
import pytest

from protocol.actions import DOWN, LEFT, MOVES, N_ACTIONS, RIGHT, STAY, UP, in_view
from protocol.config import SwarmConfig
from tests.batch_world import BatchRulesWorld
from world.engine import SwarmWorld, summed_like_numpy
from world.rules import (
    arbitrate, arbitrate_one, collision_reward, collision_reward_of, destination_reward,
    destination_reward_of,
)


def _random_tick(rng, crowded):
    """Distinct cells on a small grid and an action each. A crowded tick fills the grid nearly
    full and has most agents aim at an occupied cell: conflicts, chains, swaps and rotations."""
    width, height = (int(v) for v in rng.integers(1, 7, size=2))
    most = min(width * height, 12)
    n = max(1, most - int(rng.integers(0, 3))) if crowded else int(rng.integers(1, most + 1))
    cells = rng.choice(width * height, size=n, replace=False)
    positions = np.stack([cells % width, cells // width], axis=-1).astype(np.int64)
    actions = rng.integers(0, N_ACTIONS, size=n)
    if crowded:
        occupied = {tuple(c) for c in positions.tolist()}
        for i, cell in enumerate(positions.tolist()):
            into = [a for a in range(4) if tuple(cell + MOVES[a]) in occupied]
            if into and rng.random() < 0.8:
                actions[i] = rng.choice(into)
    return positions, actions, width, height


def _kinds(positions, actions, width, height, collided):
    """Which cases a tick holds: off-grid moves, swaps and rotations (cycles of 4+) tried,
    chains (a mover blocked by running into another mover that was blocked itself)."""
    aims = positions + MOVES[actions]
    on_grid = np.all((aims >= 0) & (aims < [width, height]), axis=-1)
    at = {tuple(c): i for i, c in enumerate(positions.tolist())}
    into = {i: at.get(tuple(c)) for i, c in enumerate(aims.tolist())
            if actions[i] != STAY and on_grid[i]}
    swaps = any(j is not None and into.get(j) == i for i, j in into.items())
    chains = any(j is not None and j in into and into[j] != i and collided[i] and collided[j]
                 for i, j in into.items())
    rotation = False
    for i, j in into.items():
        path = [i]
        while j is not None and j not in path:
            path.append(j)
            j = into.get(j)
        rotation |= j == i and len(path) >= 4
    return {"off-grid": not on_grid.all(), "swaps": swaps, "chains": chains,
            "rotations": rotation}


@pytest.mark.parametrize("count_swaps", [False, True])
def test_arbitrate_one_equals_the_batch_on_random_ticks(count_swaps):
    rng = np.random.default_rng(11 + count_swaps)
    seen = {"collisions": 0, "chains": 0, "off-grid": 0, "swaps": 0, "rotations": 0}
    for k in range(4000):
        positions, actions, width, height = _random_tick(rng, crowded=k % 2 == 0)
        after, collided = arbitrate(positions[None], actions[None], width, height, count_swaps)
        cells = [tuple(c) for c in positions.tolist()]
        one_after, one_collided = arbitrate_one(cells, actions.tolist(), width, height, count_swaps)
        assert one_after == [tuple(c) for c in after[0].tolist()], (cells, actions, width, height)
        assert one_collided == collided[0].tolist(), (cells, actions, width, height)
        seen["collisions"] += bool(collided.any())
        for kind, present in _kinds(positions, actions, width, height, collided[0]).items():
            seen[kind] += present
    assert min(seen.values()) >= 50, seen


def test_arbitrate_one_takes_plain_cells():
    cells, collided = arbitrate_one([(0, 0), (1, 0), (1, 1), (0, 1)], [RIGHT, DOWN, LEFT, UP],
                                    2, 2, True)
    assert cells == [(1, 0), (1, 1), (0, 1), (0, 0)] and collided == [False] * 4
    assert arbitrate_one([(0, 0), (1, 0)], [RIGHT, LEFT], 2, 1, True) == (
        [(0, 0), (1, 0)], [True, True])
    assert arbitrate_one([(0, 0), (1, 0)], [RIGHT, LEFT], 2, 1, False) == (
        [(1, 0), (0, 0)], [False, False])


@pytest.mark.parametrize("goal_reward", [10.0, 3.5])
def test_destination_reward_of_is_bit_equal_to_the_batch(goal_reward):
    goal = (7, 5)
    around = [(goal[0] + dx, goal[1] + dy) for dx in range(-9, 10) for dy in range(-9, 10)]
    steps = [(0, -1), (0, 1), (-1, 0), (1, 0), (0, 0), (2, 1)]
    before = np.array([cell for cell in around for _ in steps])
    after = before + np.array(steps * len(around))
    batch = destination_reward(before, after, np.array(goal), goal_reward)
    one = [destination_reward_of(tuple(b), tuple(a), goal, goal_reward)
           for b, a in zip(before.tolist(), after.tolist())]
    assert [r.hex() for r in one] == [float(r).hex() for r in batch]
    assert {0.0, goal_reward} < set(one), "further, arrived, and closer or same"


def test_collision_reward_of_is_the_batch_value():
    for hit in (False, True):
        assert collision_reward_of(hit).hex() == float(collision_reward(np.array(hit))).hex()


@pytest.mark.parametrize("n", [0, 1, 2, 5, 7, 8, 9, 15, 16, 17, 33, 127, 128, 129, 136, 255, 256,
                               257, 1000, 1024])
def test_summed_like_numpy_is_numpy_sum_bit_for_bit(n):
    rng = np.random.default_rng(n)
    for _ in range(50):
        values = rng.random(n) * 10.0 ** rng.integers(-9, 9, size=n)
        values[rng.random(n) < 0.2] *= -1
        assert summed_like_numpy(values.tolist()).hex() == float(values.sum()).hex()
    rewards = rng.choice([0.0, 10.0, 0.5 / 3, 1 / np.sqrt(2), 1 / np.sqrt(5)], size=n)
    assert summed_like_numpy(rewards.tolist()).hex() == float(rewards.sum()).hex()
    zeros = np.full(n, -0.0)
    assert summed_like_numpy(zeros.tolist()).hex() == float(zeros.sum()).hex()


def _actions(observations, rng):
    """Mostly towards the goal, sometimes random, now and then missed (``None``)."""
    actions = []
    for obs in observations:
        dx, dy = obs.goal[0] - obs.position[0], obs.goal[1] - obs.position[1]
        toward = (RIGHT if dx > 0 else LEFT) if abs(dx) >= abs(dy) and dx else (
            (DOWN if dy > 0 else UP) if dy else STAY)
        roll = rng.random()
        actions.append(None if roll < 0.03 else toward if roll < 0.6 else int(rng.integers(0, 5)))
    return actions


def _play_both(config, seed):
    """Run both worlds side by side on the same actions; what happened, for the coverage check."""
    fast, reference = SwarmWorld(config), BatchRulesWorld(config)
    rng = np.random.default_rng(seed)
    seen = {"arrived": 0, "collided": 0, "missed": 0, "hidden": 0, "rows": 0}
    while not reference.finished:
        observations = fast.observations()
        assert repr(observations) == repr(reference.observations())
        positions = reference.positions
        offsets = positions[None] - positions[:, None]
        seen["hidden"] += int((~in_view(offsets)).sum())
        actions = _actions(observations, rng)
        report = fast.apply(actions)
        assert repr(report) == repr(reference.apply(actions))
        assert np.array_equal(fast.positions, reference.positions)
        assert fast.positions.dtype == reference.positions.dtype
        assert np.array_equal(fast.arrived, reference.arrived)
        seen["arrived"] += int(fast.arrived.sum())
        seen["collided"] += len(report.collided)
        seen["missed"] += len(report.missed)
        seen["rows"] += report.episode_row is not None
    assert fast.finished and (fast.tick, fast.violations) == (reference.tick, reference.violations)
    return seen


@pytest.mark.parametrize("n_agents, width, height, count_swaps", [
    (8, 11, 11, True),  # the swarm's default: everybody sees everybody
    (8, 40, 40, True),  # not everybody sees everybody
    (32, 40, 40, True),
    (12, 5, 5, False),  # crowded
    (5, 5, 5, True),
    (9, 12, 30, False),
])
@pytest.mark.parametrize("seed", [0, 1])
def test_swarm_world_equals_the_batch_rules_world(n_agents, width, height, count_swaps, seed):
    config = SwarmConfig(run_id="one-world", n_agents=n_agents, width=width, height=height,
                         seed=seed, episodes=4, max_steps=40, count_swaps=count_swaps)
    seen = _play_both(config, seed)
    assert seen["rows"] == config.episodes
    assert seen["arrived"] and seen["collided"] and seen["missed"], seen
    assert bool(seen["hidden"]) == (max(width, height) > 11), seen


@pytest.mark.parametrize("agents,grid", [(8, (11, 11)), (9, (40, 40))])
def test_observations_by_rank_are_the_observations_in_rank_order(agents, grid):
    config = SwarmConfig(run_id="ranked", n_agents=agents, width=grid[0], height=grid[1],
                         episodes=2, max_steps=6, seed=4)
    world = SwarmWorld(config)
    rng = np.random.default_rng(0)
    while not world.finished:
        by_rank = list(world.observations_by_rank())
        assert [o.rank for o in by_rank] == list(range(agents))
        assert by_rank == sorted(world.observations(), key=lambda o: o.rank)
        world.apply(rng.integers(0, 5, size=agents).tolist())
