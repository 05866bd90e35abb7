"""Priority inheritance over the agents' own orders (``--arbitration pibt``): an agent's announced
order, the one planner (``world.pibt.plan``) that serves the oracle and the learners, a missed
intent that stays, and a learning swarm that nobody collides in."""

import numpy as np
import pytest

from nnql_swarm.learning.known_map import fresh_map, map_size, plan_field
from nnql_swarm.learning.fields import (
    NB_FIELDS, NB_ID, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_PREV_X, NB_PREV_Y, NB_X, NB_Y, V_CROWD,
    V_FINAL, VALUES_SIZE,
)
from nnql_swarm.learning.learner import UNREACHED, hindrance, move_length, preference_ranks
from nnql_swarm.protocol.actions import N_ACTIONS, STAY, target_x, target_y
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, swarm_world
from nnql_swarm.world.engine import SwarmWorld
from nnql_swarm.world.pibt import FAR, TIES, _tie, goal_distances, plan


def known_field(width, height, goal):
    """A known map of no walls, its distance field current for ``goal``."""
    wmap = np.zeros(map_size(width, height), dtype=np.int64)
    fresh_map(wmap)
    plan_field(wmap, 0, 0, goal[0], goal[1], width, height)
    return wmap


NO_ROWS = np.zeros((0, NB_FIELDS), dtype=np.int64)


def coming_from_the_left(known: bool, seen_before: bool) -> np.ndarray:
    """One neighbour row: an agent at (1, 2), next to (2, 2), coming right into it (its
    announced move where ``known``, else the move it made last where ``seen_before``)."""
    row = np.zeros((1, NB_FIELDS), dtype=np.int64)
    row[0, NB_ID], row[0, NB_X], row[0, NB_Y] = 1, 1, 2
    row[0, NB_KNOWN] = int(known)
    row[0, NB_NEXT_X], row[0, NB_NEXT_Y] = (2, 2) if known else (1, 2)
    row[0, NB_PREV_X], row[0, NB_PREV_Y] = (0, 2) if seen_before else (-1, -1)
    return row


def test_an_order_goes_by_the_known_way_then_by_learned_crowd_value_then_by_tie():
    """From (2, 2) to (4, 4) on an open map: right and down leave 3 to go, staying 4, up and
    left 5 each. Lengths come first; the learned collision-avoidance values (Eq. 6, not Q_final)
    order the moves as short that bring the agent nearer; the tie-breakers the rest (how it makes
    way), whatever their values; a random step (or staying on the goal) goes first."""
    wmap = known_field(5, 5, (4, 4))
    lengths = [move_length(wmap, 2, 2, a, 5, 5) for a in range(N_ACTIONS)]
    nearer = [a for a in range(N_ACTIONS) if lengths[a] == 3]
    away = [a for a in range(N_ACTIONS) if lengths[a] == 5]
    assert len(nearer) == 2 and len(away) == 2 and lengths[STAY] == 4
    values = np.zeros(VALUES_SIZE)  # Q_final from V_FINAL, Q_CA(a) from V_CROWD
    ties = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    ranks = np.zeros(N_ACTIONS, dtype=np.int64)
    preference_ranks(values, ties, wmap, 2, 2, 5, 5, -1, True, ranks, 0, NO_ROWS, 0)
    by_tie = sorted(nearer, key=lambda a: -ties[a])
    assert [ranks[a] for a in by_tie] == [0, 1] and ranks[STAY] == 2
    assert sorted(ranks[away]) == [3, 4]
    values[V_FINAL + by_tie[0]] = 9.0  # Q_final does not order them
    preference_ranks(values, ties, wmap, 2, 2, 5, 5, -1, True, ranks, 0, NO_ROWS, 0)
    assert [ranks[a] for a in by_tie] == [0, 1]
    values[V_CROWD + by_tie[-1]] = 1.0  # a learned crowd value outranks the tie-breaker there
    away_by_tie = sorted(away, key=lambda a: -ties[a])
    values[V_CROWD + away_by_tie[-1]] = 1.0  # but not among the moves that make way
    preference_ranks(values, ties, wmap, 2, 2, 5, 5, -1, True, ranks, 0, NO_ROWS, 0)
    assert ranks[by_tie[-1]] == 0 and ranks[by_tie[0]] == 1
    assert [ranks[a] for a in away_by_tie] == [3, 4]
    preference_ranks(values, ties, wmap, 2, 2, 5, 5, STAY, True, ranks, 0, NO_ROWS, 0)  # a random step
    assert ranks[STAY] == 0 and ranks[by_tie[-1]] == 1
    assert sorted(ranks) == list(range(N_ACTIONS))
    off_grid = [a for a in range(N_ACTIONS) if a != STAY
                and (target_x(0, a, 5), target_y(0, a, 5)) == (0, 0)]
    assert off_grid and move_length(wmap, 0, 0, off_grid[0], 5, 5) == UNREACHED


def test_a_pushed_agent_steps_aside_rather_than_on_ahead_of_its_pusher():
    """On its goal at (2, 2), an agent offers to stay, then its four moves, all one step from
    the goal. A neighbour coming right into its cell would find the cell on its right in its way
    (hindrance): that move goes last, whatever the tie-breakers, whether the neighbour announced
    its move or was seen making it last tick; a neighbour not seen coming hinders nothing."""
    wmap = known_field(5, 5, (2, 2))
    right = next(a for a in range(N_ACTIONS) if (target_x(2, a, 5), target_y(2, a, 5)) == (3, 2))
    ties = np.array([0.1, 0.2, 0.3, 0.4, 0.5])
    ties[right] = 0.9  # the tie-breakers would put it first
    ranks = np.zeros(N_ACTIONS, dtype=np.int64)
    values = np.zeros(VALUES_SIZE)
    for known, seen_before in ((True, False), (False, True)):
        nb = coming_from_the_left(known, seen_before)
        assert [hindrance(nb, 1, 2, 2, a, 5, 5) for a in range(N_ACTIONS)] == [
            int(a == right) for a in range(N_ACTIONS)]
        preference_ranks(values, ties, wmap, 2, 2, 5, 5, STAY, False, ranks, 0, nb, 1)
        assert ranks[STAY] == 0 and ranks[right] == N_ACTIONS - 1
    preference_ranks(values, ties, wmap, 2, 2, 5, 5, STAY, False, ranks, 0,
                     coming_from_the_left(False, False), 1)
    assert ranks[STAY] == 0 and ranks[right] == 1


def plan_once(x, y, gx, gy, width, height, step, learned, ranks, walls=()):
    """One step of ``plan`` under step-aside for agents at ``x, y`` and ``walls`` cells."""
    n = len(x)
    bodies = n + len(walls)
    cells = width * height
    xs = np.array(list(x) + [c[0] for c in walls], dtype=np.int64)
    ys = np.array(list(y) + [c[1] for c in walls], dtype=np.int64)
    goal_x = np.array(list(gx) + [-1] * len(walls), dtype=np.int64)
    goal_y = np.array(list(gy) + [-1] * len(walls), dtype=np.int64)
    size = max(cells, bodies)
    rows = [np.zeros(size, dtype=np.int64) for _ in range(12)]
    priority, closest = rows[7], rows[9]
    priority[:n] = np.arange(n)[::-1]
    closest[:n] = FAR
    actions = np.zeros(bodies, dtype=np.int64)
    distances = np.zeros(n * cells, dtype=np.int64)
    plan(xs, ys, goal_x, goal_y, np.zeros(bodies, dtype=bool), bodies, n, width, height, True,
         priority, closest, actions, distances, rows[0], rows[1], np.zeros(bodies, dtype=bool),
         rows[2], rows[3], rows[4], rows[5], rows[6], rows[8], rows[10], rows[11], step,
         np.full(n, -1, dtype=np.int64), learned, ranks)
    return actions[:n], distances


@pytest.mark.parametrize("seed", range(20))
def test_orders_by_distance_are_the_oracle_itself(seed):
    """``plan`` with each agent's order its cells by distance and tie-breaker (what the oracle
    computes) plans exactly what the oracle plans: one planner, two sources of preference."""
    rng = np.random.default_rng(seed)
    width = height = 7
    cells = rng.permutation(width * height)
    walls = [(int(c % width), int(c // width)) for c in cells[:6]]
    n = 12
    starts, goals = cells[6:6 + n], cells[6 + n:6 + 2 * n]
    x, y = starts % width, starts // width
    gx, gy = goals % width, goals // width
    step = int(rng.integers(0, 50))
    none = np.zeros(n * N_ACTIONS, dtype=np.int64)
    oracle, distances = plan_once(x, y, gx, gy, width, height, step, False, none, walls)
    ranks = np.zeros(n * N_ACTIONS, dtype=np.int64)
    for i in range(n):
        keys = []
        for a in range(N_ACTIONS):
            tx, ty = target_x(int(x[i]), a, width), target_y(int(y[i]), a, height)
            c = ty * width + tx
            off = a != STAY and (tx, ty) == (x[i], y[i])
            keys.append((1, a) if off else (0, distances[i * width * height + c] * TIES
                                            + _tie(i, c, step)))
        for rank, a in enumerate(sorted(range(N_ACTIONS), key=keys.__getitem__)):
            ranks[i * N_ACTIONS + a] = rank if keys[a][0] == 0 else N_ACTIONS
    learned, _ = plan_once(x, y, gx, gy, width, height, step, True, ranks, walls)
    assert np.array_equal(learned, oracle)


def test_a_missed_intent_stays_and_nobody_collides():
    """Agent 1 missed the deadline: the world settles the others around it, it stays, and the
    agent that wanted its cell takes another or waits."""
    config = SwarmConfig(**PRESETS["pibt-nnql"], n_agents=4, width=6, height=6, seed=3)
    world = SwarmWorld(config)
    before = world.cells
    # everyone says it wants agent 1's cell first, where it can
    orders = []
    for i, (x, y) in enumerate(before):
        toward = min(range(N_ACTIONS - 1), key=lambda a: abs(target_x(x, a, 6) - before[1][0])
                     + abs(target_y(y, a, 6) - before[1][1]))
        orders.append(None if i == 1 else (toward, *[a for a in range(N_ACTIONS) if a != toward]))
    report = world.apply([None if o is None else o[0] for o in orders], None, orders)
    assert world.cells[1] == before[1] and report.missed == (1,)
    assert not report.collided and not report.violations
    assert len(set(world.cells)) == 4


def test_a_learning_swarm_under_priority_inheritance_never_collides_and_comes_home():
    """32 learners on a random 19 x 19 map with walls, from scratch: nobody collides, ever, and
    after a few episodes (random steps and all) nearly every agent ends on its goal."""
    config = SwarmConfig(**{**PRESETS["pibt-nnql"]}, n_agents=32, width=19, height=19,
                         obstacle_density=0.2, max_steps=128, seed=5)
    episodes = Batch(swarm_world(config), [config]).play(12)
    assert not episodes.collisions.any() and not episodes.violations.any()
    assert episodes.arrived[0, -4:].mean() / 32 >= 0.97
