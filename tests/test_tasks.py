"""Lifelong tasks (``--tasks lifelong``, ``world.tasks``): the goals drawn ahead, their renewal on
arrival, and a lifelong swarm that counts every goal once."""

import numpy as np

from nnql_swarm.protocol.jit import flags, ints
from nnql_swarm.protocol.actions import N_ACTIONS, target_x, target_y
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.protocol.walls import layout, regions
from nnql_swarm.sim.runs import Batch, swarm_world
from nnql_swarm.world.engine import SwarmWorld
from nnql_swarm.world.rules import ROW_ARRIVED, ROW_GOALS
from nnql_swarm.world.tasks import goal_sequences, renew_goals


def test_each_goal_is_drawn_in_the_agents_region_never_the_one_just_reached():
    rows = ("......@...", "......@...", "@@@@@@@...", "..........", "..........")
    walls = layout(0, 10, 5, 0.0, rows)[0]
    region = regions(10, 5, walls)
    first = np.array([[0, 0], [9, 4], [1, 1]])
    sequences = goal_sequences(7, 3, 10, 5, walls, first, 200)
    assert sequences.shape == (3, 200, 2)
    for agent, goals in enumerate(sequences):
        path = [first[agent], *goals]
        for before, after in zip(path, path[1:]):
            assert tuple(before) != tuple(after)
            assert region[after[1] * 10 + after[0]] == region[first[agent][1] * 10 + first[agent][0]]
    cells = {tuple(g) for g in sequences[0]}
    assert len(cells) == 12, "the small room's 12 cells, each drawn in 199 draws"
    assert np.array_equal(goal_sequences(7, 3, 10, 5, walls, first, 200), sequences)
    assert not np.array_equal(goal_sequences(7, 4, 10, 5, walls, first, 200), sequences)
    assert np.array_equal(goal_sequences(7, 3, 10, 5, walls, first[:2], 200), sequences[:2]), \
        "an agent's goals are its own: they do not depend on the others"


def test_an_agent_that_arrived_has_its_next_goal_and_the_goal_counts():
    goal_x, goal_y, arrived = ints([1, 2, 3]), ints([1, 2, 3]), flags([False, True, True])
    sequences = ints([5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 0, 0])  # 3 agents, 2 goals each, flat
    next_goal, row = ints([0, 0, 1]), ints([0, 0, 2, 0, 0])
    renew_goals(goal_x, goal_y, arrived, 3, sequences, 2, next_goal, row)
    assert (list(goal_x), list(goal_y)) == ([1, 7, 0], [1, 7, 0])
    assert not any(arrived) and list(next_goal) == [0, 1, 2]
    assert row[ROW_ARRIVED] == 0 and row[ROW_GOALS] == 2


def test_a_lifelong_episode_runs_its_steps_and_its_throughput_is_goals_a_step():
    config = SwarmConfig(**PRESETS["oracle"], tasks="lifelong", n_agents=16, width=16,
                         height=16, obstacle_density=0.2, max_steps=60, seed=4)
    assert config.on_target == "step-aside"
    episodes = Batch(swarm_world(config), [config]).play(3)
    assert (episodes.steps == 60).all() and (episodes.goals > 16).all()
    assert not episodes.collisions.any() and not episodes.violations.any()
    row = episodes.swarm_row(0, 1, 16)
    assert row["throughput"] == row["goals"] / 60


def test_the_world_hands_each_agent_its_drawn_goals_in_turn():
    """The world process's engine renews goals as drawn (``goal_sequences``, the simulator's
    too): each agent's goals, as its observations show them, are its first and then its drawn
    ones in order, one more for every goal it reached, and nobody collides."""
    config = SwarmConfig(**PRESETS["pibt-nnql"], tasks="lifelong", n_agents=6, width=10,
                         height=10, max_steps=40, seed=9, episodes=1)
    world = SwarmWorld(config)
    sequences = goal_sequences(9, 0, 10, 10, config.walls(), world.goals, 40)
    seen: list[list[tuple[int, int]]] = [[tuple(g)] for g in world.goals.tolist()]
    for _ in range(40):
        orders = []
        for obs in world.observations():
            (x, y), (gx, gy) = obs.position, obs.goal
            orders.append(tuple(sorted(range(N_ACTIONS), key=lambda a: abs(
                target_x(x, a, 10) - gx) + abs(target_y(y, a, 10) - gy))))
        report = world.apply([o[0] for o in orders], None, orders)
        assert not report.collided and not report.violations
        for agent, goal in enumerate(world.observations()):
            if tuple(goal.goal) != seen[agent][-1]:
                seen[agent].append(tuple(goal.goal))
    reached = world.episode_row()["goals"]
    assert reached == sum(len(goals) - 1 for goals in seen) > 6
    for agent, goals in enumerate(seen):
        assert goals[1:] == [tuple(g) for g in sequences[agent, :len(goals) - 1].tolist()]
