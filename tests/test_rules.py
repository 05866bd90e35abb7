"""World rules: every collision case of arbitrate, its invariants over random ticks, the rewards,
the world's step (arrivals, scripted bodies, the running score) and the invariant checks."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from nnql_swarm.protocol.actions import DOWN, LEFT, MOVES, N_ACTIONS, RIGHT, STAY, UP, intended_cell
from nnql_swarm.world.rules import (
    CA_REWARD, GOAL_REWARD, STAY_REWARD, ROW_AGENT_STEPS, ROW_ARRIVED, ROW_COLLISIONS, ROW_FLOATS, ROW_INTS,
    ROW_REWARD, ROW_REWARD_CA, ROW_REWARD_DS, ROW_STEPS, arbitrate, collision_reward,
    Bodies, Outcome, Rules, Scratch, Score, destination_reward, shared_cells, shortest_steps,
    swaps_through, world_step,
)

WIDTH, HEIGHT = 5, 4


def tick(cells, actions, count_swaps=False, width=WIDTH, height=HEIGHT):
    """One tick of :func:`arbitrate`: returns (new cells as tuples, collided as bools)."""
    n = len(cells)
    x = np.array([c[0] for c in cells], dtype=np.int64)
    y = np.array([c[1] for c in cells], dtype=np.int64)
    final_x, final_y = np.zeros(n, np.int64), np.zeros(n, np.int64)
    collided = np.zeros(n, bool)
    occupancy = np.zeros(width * height, np.int64)
    arbitrate(x, y, np.array(actions, dtype=np.int64), n, width, height, count_swaps, final_x,
              final_y, collided, occupancy, np.zeros(n, bool))
    assert not occupancy.any(), "the scratch grid is left clean"
    return list(zip(final_x.tolist(), final_y.tolist())), collided.tolist()


def plain_tick(cells, actions, count_swaps=False, width=WIDTH, height=HEIGHT):
    """The same tick with the kernel run as plain Python on lists."""
    n = len(cells)
    final_x, final_y, collided = [0] * n, [0] * n, [False] * n
    arbitrate.py_func([c[0] for c in cells], [c[1] for c in cells], list(actions), n, width,
                      height, count_swaps, final_x, final_y, collided, [0] * (width * height),
                      [False] * n)
    return list(zip(final_x, final_y)), collided


def test_free_moves_go_through():
    cells, collided = tick([(0, 0), (3, 3)], [RIGHT, UP])
    assert cells == [(1, 0), (3, 2)]
    assert collided == [False, False]


def test_two_into_one_cell_both_stay_and_both_collide():
    cells, collided = tick([(0, 0), (2, 0)], [RIGHT, LEFT])
    assert cells == [(0, 0), (2, 0)]
    assert collided == [True, True]


def test_four_into_one_cell():
    cells, collided = tick([(1, 0), (0, 1), (2, 1), (1, 2)], [DOWN, RIGHT, LEFT, UP])
    assert cells == [(1, 0), (0, 1), (2, 1), (1, 2)]
    assert collided == [True] * 4


def test_moving_into_a_staying_occupant_collides_both():
    cells, collided = tick([(0, 0), (1, 0)], [RIGHT, STAY])
    assert cells == [(0, 0), (1, 0)]
    assert collided == [True, True]


def test_blocking_chain_resolves_to_a_fixed_point():
    # A -> B's cell, B -> C's cell, C stays: C blocks B, which then blocks A.
    cells, collided = tick([(0, 0), (1, 0), (2, 0)], [RIGHT, RIGHT, STAY])
    assert cells == [(0, 0), (1, 0), (2, 0)]
    assert collided == [True, True, True]


def test_chain_blocked_by_a_head_on_conflict_at_its_front():
    # A -> B's cell, B -> (2, 0) where C also goes: B and C collide, then A runs into B.
    cells, collided = tick([(0, 0), (1, 0), (3, 0)], [RIGHT, RIGHT, LEFT])
    assert cells == [(0, 0), (1, 0), (3, 0)]
    assert collided == [True, True, True]


def test_following_into_a_vacated_cell_is_no_collision():
    cells, collided = tick([(0, 0), (1, 0), (2, 0)], [RIGHT, RIGHT, RIGHT])
    assert cells == [(1, 0), (2, 0), (3, 0)]
    assert collided == [False, False, False]


@pytest.mark.parametrize("count_swaps", [False, True])
def test_rotation_all_move(count_swaps):
    # On a 4-neighbour grid every cycle has even length, so the smallest rotation has 4 agents
    # (a 2x2 block turning clockwise); a 3-cycle of unit moves cannot exist.
    start = [(0, 0), (1, 0), (1, 1), (0, 1)]
    cells, collided = tick(start, [RIGHT, DOWN, LEFT, UP], count_swaps)
    assert cells == [(1, 0), (1, 1), (0, 1), (0, 0)]
    assert collided == [False] * 4


def test_rotation_of_eight_around_a_ring_all_move():
    ring = [(0, 0), (1, 0), (2, 0), (2, 1), (2, 2), (1, 2), (0, 2), (0, 1)]
    actions = [RIGHT, RIGHT, DOWN, DOWN, LEFT, LEFT, UP, UP]
    cells, collided = tick(ring, actions, count_swaps=True)
    assert cells == ring[1:] + ring[:1]
    assert not any(collided)


def test_swap_passes_through_when_swaps_are_not_counted():
    cells, collided = tick([(0, 0), (1, 0)], [RIGHT, LEFT], count_swaps=False)
    assert cells == [(1, 0), (0, 0)]
    assert collided == [False, False]


def test_swap_collides_both_when_swaps_are_counted():
    cells, collided = tick([(0, 0), (1, 0)], [RIGHT, LEFT], count_swaps=True)
    assert cells == [(0, 0), (1, 0)]
    assert collided == [True, True]


def test_blocked_swap_blocks_its_follower():
    # C follows A into A's cell; A's swap with B is blocked, so C runs into A.
    cells, collided = tick([(1, 0), (2, 0), (0, 0)], [RIGHT, LEFT, RIGHT], count_swaps=True)
    assert cells == [(1, 0), (2, 0), (0, 0)]
    assert collided == [True, True, True]


@pytest.mark.parametrize(
    "cell, action", [((0, 0), LEFT), ((0, 0), UP), ((WIDTH - 1, HEIGHT - 1), RIGHT), ((2, HEIGHT - 1), DOWN)]
)
def test_moving_off_the_grid_stays_without_collision(cell, action):
    cells, collided = tick([cell], [action])
    assert cells == [cell]
    assert collided == [False]


def test_off_grid_mover_counts_as_staying_for_others():
    cells, collided = tick([(0, 0), (1, 0)], [LEFT, LEFT])
    assert cells == [(0, 0), (1, 0)]
    assert collided == [True, True]


@st.composite
def ticks(draw):
    width = draw(st.integers(1, 6))
    height = draw(st.integers(1, 6))
    n = draw(st.integers(1, min(8, width * height)))
    cells = draw(st.lists(st.integers(0, width * height - 1), min_size=n, max_size=n, unique=True))
    positions = [(c % width, c // width) for c in cells]
    actions = draw(st.lists(st.integers(0, N_ACTIONS - 1), min_size=n, max_size=n))
    return positions, actions, width, height, draw(st.booleans())


@settings(max_examples=400, deadline=None)
@given(ticks())
def test_invariants_of_a_tick(case):
    cells, actions, width, height, count_swaps = case
    moved, collided = tick(cells, actions, count_swaps, width, height)
    assert plain_tick(cells, actions, count_swaps, width, height) == (moved, collided)
    target = [intended_cell(x, y, a, width, height) for (x, y), a in zip(cells, actions)]
    n = len(cells)

    assert len(set(moved)) == n, "two agents share a cell"
    assert all(0 <= x < width and 0 <= y < height for x, y in moved), "an agent left the grid"
    # Collided agents stay; the others reach the cell they aimed at.
    for i in range(n):
        assert moved[i] == (cells[i] if collided[i] else target[i])
    # Every collision has a cause: the agent was blocked, or someone aimed at its cell.
    for i in range(n):
        if collided[i]:
            assert target[i] != cells[i] or any(target[j] == cells[i] for j in range(n) if j != i)
    if count_swaps:
        for i in range(n):
            for j in range(n):
                assert not (i != j and moved[i] == cells[j] and moved[j] == cells[i]), \
                    "swap-through while swaps count as collisions"


@settings(max_examples=200, deadline=None)
@given(ticks())
def test_without_swaps_a_tick_equals_the_one_with_swaps_unless_a_swap_is_tried(case):
    cells, actions, width, height, _ = case
    target = [intended_cell(x, y, a, width, height) for (x, y), a in zip(cells, actions)]
    n = len(cells)
    tries_swap = any(i != j and target[i] == cells[j] and target[j] == cells[i]
                     and target[i] != cells[i] for i in range(n) for j in range(n))
    if not tries_swap:
        assert tick(cells, actions, False, width, height) == tick(cells, actions, True, width, height)


def test_destination_reward_closer_same_further_arrived():
    goal = (5, 5)
    assert destination_reward(5, 0, 5, 1, *goal, GOAL_REWARD, STAY_REWARD) == pytest.approx(1 / 4)
    assert destination_reward(2, 1, 2, 1, *goal, GOAL_REWARD, STAY_REWARD) == pytest.approx(0.5 / 5)
    assert destination_reward(5, 1, 5, 0, *goal, GOAL_REWARD, STAY_REWARD) == 0.0
    assert destination_reward(5, 4, 5, 5, *goal, GOAL_REWARD, STAY_REWARD) == GOAL_REWARD
    assert destination_reward(5, 4, 5, 5, *goal, 3.5, STAY_REWARD) == 3.5


def test_destination_reward_equal_distance_by_exact_integers():
    # (3, 4) and (4, 3) lie at the same distance 5 from the origin: "stayed the same".
    assert destination_reward(3, 4, 4, 3, 0, 0, GOAL_REWARD, STAY_REWARD) == pytest.approx(0.5 / 5)


def test_collision_reward():
    assert [collision_reward(False), collision_reward(True)] == [CA_REWARD, 0.0]


def test_shortest_steps_is_manhattan():
    assert shortest_steps(0, 0, 3, 2) == 5 and shortest_steps(4, 1, 4, 1) == 0


def test_move_table_matches_action_names():
    assert MOVES[UP].tolist() == [0, -1] and MOVES[DOWN].tolist() == [0, 1]
    assert MOVES[LEFT].tolist() == [-1, 0] and MOVES[RIGHT].tolist() == [1, 0]
    assert MOVES[STAY].tolist() == [0, 0]
    for a in range(N_ACTIONS):
        assert intended_cell(2, 2, a, 5, 5) == (2 + MOVES[a][0], 2 + MOVES[a][1])


class Step:
    """One world of :func:`world_step` over its buffers."""

    def __init__(self, cells, goals, learns=None, width=WIDTH, height=HEIGHT, count_swaps=True,
                 step_aside=False):
        n = len(cells)
        self.step_aside = step_aside
        self.arrival = np.zeros(n, np.int64)
        self.n, self.width, self.height, self.count_swaps = n, width, height, count_swaps
        self.x, self.y = ints([c[0] for c in cells]), ints([c[1] for c in cells])
        self.gx, self.gy = ints([g[0] for g in goals]), ints([g[1] for g in goals])
        self.learns = np.array(learns or [True] * n)
        self.arrived = np.zeros(n, bool)
        self.arrival = np.zeros(n, np.int64)
        self.row, self.row_f = np.zeros(ROW_INTS, np.int64), np.zeros(ROW_FLOATS)

    def __call__(self, actions):
        n = self.n
        self.collided, self.r_ds, self.r_ca = np.zeros(n, bool), np.zeros(n), np.zeros(n)
        self.actions = ints(actions)
        self.before_x, self.before_y = np.zeros(n, np.int64), np.zeros(n, np.int64)
        rules = Rules(n, self.width, self.height, self.count_swaps, self.step_aside, GOAL_REWARD,
                      STAY_REWARD)
        bodies = Bodies(self.x, self.y, self.gx, self.gy, self.learns, self.arrived, self.arrival)
        outcome = Outcome(self.before_x, self.before_y, self.collided, self.r_ds, self.r_ca)
        scratch = Scratch(np.zeros(self.width * self.height, np.int64), np.zeros(n, bool))
        return world_step(rules, bodies, self.actions, outcome, scratch,
                          Score(self.row, self.row_f))


def ints(values):
    return np.array(values, dtype=np.int64)


def test_world_step_moves_rewards_arrivals_and_the_running_score():
    step = Step([(0, 0), (3, 0)], goals=[(1, 0), (2, 3)])
    everyone = step([RIGHT, LEFT])
    assert not everyone
    assert (step.x.tolist(), step.y.tolist()) == ([1, 2], [0, 0])
    assert (step.before_x.tolist(), step.before_y.tolist()) == ([0, 3], [0, 0])
    assert step.arrived.tolist() == [True, False]
    assert step.r_ds.tolist() == [GOAL_REWARD, 1 / 3] and step.r_ca.tolist() == [CA_REWARD] * 2
    assert step.row[ROW_STEPS] == 1 and step.row[ROW_ARRIVED] == 1
    assert step.row[ROW_AGENT_STEPS] == 2 and step.row[ROW_COLLISIONS] == 0
    assert step.row_f[ROW_REWARD_DS] == GOAL_REWARD + 1 / 3
    assert step.row_f[ROW_REWARD_CA] == 2 * CA_REWARD
    assert step.row_f[ROW_REWARD] == GOAL_REWARD + 1 / 3 + 2 * CA_REWARD
    # The arrived agent stays whatever it says, earns nothing and is still in the way.
    step([LEFT, UP])  # agent 1 tries to leave the grid: it stays, "same distance"
    assert step.actions[0] == STAY and (step.x[0], step.y[0]) == (1, 0)
    assert step.r_ds.tolist() == [0.0, 0.5 / 3] and step.r_ca[0] == 0.0
    assert step.row[ROW_AGENT_STEPS] == 3
    assert [step([STAY, DOWN]) for _ in range(3)] == [False, False, True]
    assert step.row[ROW_ARRIVED] == 2


def test_a_collision_counts_once_per_learner_involved_and_pays_no_ca_reward():
    step = Step([(0, 0), (2, 0)], goals=[(4, 3), (0, 3)])
    step([RIGHT, LEFT])
    assert step.collided.tolist() == [True, True] and step.r_ca.tolist() == [0.0, 0.0]
    assert step.row[ROW_COLLISIONS] == 2


def test_scripted_bodies_move_by_the_rules_but_earn_and_count_nothing():
    step = Step([(0, 0), (2, 0)], goals=[(4, 3), (-1, -1)], learns=[True, False])
    step([RIGHT, LEFT])
    assert step.collided.tolist() == [True, True]
    assert step.row[ROW_COLLISIONS] == 1 and step.row[ROW_AGENT_STEPS] == 1
    assert step.r_ds[1] == 0.0 and step.r_ca[1] == 0.0 and not step.arrived.any()


def test_invariant_checks_count_shared_cells_and_swaps():
    occupancy = np.zeros(36, np.int64)
    assert shared_cells(ints([0, 1, 5]), ints([0, 0, 5]), 3, 6, occupancy) == 0
    assert shared_cells(ints([0, 0, 5]), ints([1, 1, 5]), 3, 6, occupancy) == 2
    assert swaps_through(ints([0, 1, 5]), ints([0, 0, 5]), ints([1, 0, 5]), ints([0, 0, 5]), 3, 6,
                         occupancy) == 2
    assert swaps_through(ints([0, 1, 5]), ints([0, 0, 5]), ints([1, 2, 5]), ints([0, 0, 4]), 3, 6,
                         occupancy) == 0
    assert not occupancy.any()


def test_under_step_aside_an_arrived_agent_may_leave_and_its_last_arrival_counts():
    step = Step([(0, 0), (3, 3)], goals=[(1, 0), (0, 3)], step_aside=True)
    step([RIGHT, LEFT])
    assert step.arrived.tolist() == [True, False] and step.arrival[0] == 1
    step([STAY, LEFT])  # it stays by choice: still arrived, its steps no longer count
    assert step.row[ROW_AGENT_STEPS] == 3 and step.row[ROW_ARRIVED] == 1
    step([DOWN, STAY])  # it makes way: no longer arrived, its parked steps count again
    assert step.actions[0] == DOWN and (step.x[0], step.y[0]) == (1, 1)
    assert not step.arrived[0] and step.row[ROW_ARRIVED] == 0
    assert step.r_ds[0] == 0.0 and step.r_ca[0] == 0.0  # a step taken arrived earns nothing
    assert step.row[ROW_AGENT_STEPS] == 3 + 1 + 2
    # Back on its goal at step 4, the other on its own: every agent on its goal at once
    assert step([UP, LEFT])
    assert step.arrived.tolist() == [True, True] and step.arrival.tolist() == [4, 4]
    assert step.row[ROW_AGENT_STEPS] == 4 + 4  # each agent's last arrival step


def test_under_park_an_arrived_agent_stays_whatever_it_says():
    step = Step([(0, 0)], goals=[(1, 0)])
    step([RIGHT])
    step([DOWN])
    assert step.actions[0] == STAY and step.arrived[0] and step.arrival[0] == 1


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 40), st.integers(0, 40), st.booleans()), min_size=1,
                max_size=30), st.booleans(), st.booleans())
def test_every_agents_neighbours_are_packed_by_sees_between_every_two_cells(agents, sees_all,
                                                                             parks):
    """``world.sight.pack_seen``: agent ``i``'s slice of the packing holds exactly the others
    it sees (``sees``; every other where the grid fits in the view) as ``(id, x, y)`` in id
    order, and, where arrived agents park, the ids of the arrived ones among them."""
    from nnql_swarm.protocol.actions import sees
    from nnql_swarm.protocol.messages import CELL_TYPE, unpack_ids, unpack_neighbours
    from nnql_swarm.world.sight import pack_seen

    n = len(agents)
    xs, ys = (np.array(values, dtype=np.int64) for values in list(zip(*agents))[:2])
    arrived = np.array([a for _, _, a in agents], dtype=bool)
    seen, parked = np.zeros(3 * n * (n - 1), CELL_TYPE), np.zeros(n * (n - 1), CELL_TYPE)
    seen_at, parked_at = np.zeros(n + 1, np.int64), np.zeros(n + 1, np.int64)
    pack_seen(xs, ys, arrived, n, sees_all, parks, seen, parked, seen_at, parked_at)
    seen_bytes, parked_bytes = seen.tobytes(), parked.tobytes()
    for i, (ax, ay, _) in enumerate(agents):
        others = [(j, bx, by) for j, (bx, by, _) in enumerate(agents)
                  if j != i and (sees_all or sees(ax, ay, bx, by))]
        packed = seen_bytes[seen_at[i]:seen_at[i + 1]]
        assert unpack_neighbours(packed).tolist() == [list(o) for o in others]
        ids = unpack_ids(parked_bytes[parked_at[i]:parked_at[i + 1]]).tolist()
        assert ids == ([j for j, _, _ in others if agents[j][2]] if parks else [])


def test_the_worlds_step_over_flat_buffers_moves_renews_goals_refuses_and_counts_the_invariants():
    """``world.step.world_move``, the step the world process runs (compiled ahead of time where
    it is built): the moves of :func:`world_step`, then a lifelong run's next goals (who reached
    one, flagged), the reward of a refused first choice, and the invariants counted (none broken
    here: the checks themselves are tested above)."""
    from nnql_swarm.world.pibt import UNWANTED as UNWANTED_RANK
    from nnql_swarm.world.step import MOVE_EVERYONE, MOVE_SHARED, MOVE_SWAPPED, world_move

    def move(x, y, gx, gy, actions, count_swaps=False, refuse=False, ranks=(), lifelong=False,
             tasks=(), next_goal=(0, 0)):
        n = len(x)
        buffers = {"x": ints(x), "y": ints(y), "gx": ints(gx), "gy": ints(gy),
                   "arrived": np.zeros(n, bool), "arrival": ints([0] * n),
                   "actions": ints(actions), "r_ca": np.zeros(n), "row": ints([0] * ROW_INTS),
                   "row_f": np.zeros(ROW_FLOATS), "reached": np.zeros(n, bool),
                   "next_goal": ints(next_goal), "out": ints([0, 0, 0])}
        b = buffers
        world_move(n, WIDTH, HEIGHT, count_swaps, False, GOAL_REWARD, STAY_REWARD, b["x"], b["y"],
                   b["gx"], b["gy"], np.ones(n, bool), b["arrived"], b["arrival"], b["actions"],
                   ints([0] * n), ints([0] * n), np.zeros(n, bool), np.zeros(n), b["r_ca"],
                   ints([0] * WIDTH * HEIGHT), np.zeros(n, bool), b["row"], b["row_f"], n,
                   refuse, ints(ranks), lifelong, ints(tasks), 2, b["next_goal"], b["reached"],
                   b["out"])
        return b

    swap = move([0, 1], [0, 0], [4, 0], [3, 0], [RIGHT, LEFT])  # swaps do not count: they pass
    assert (swap["x"].tolist(), swap["out"][MOVE_SWAPPED], swap["out"][MOVE_SHARED]) == (
        [1, 0], 0, 0)
    blocked = move([0, 1], [0, 0], [4, 0], [3, 0], [RIGHT, LEFT], count_swaps=True)
    assert (blocked["x"].tolist(), blocked["out"][MOVE_SWAPPED]) == ([0, 1], 0)
    arrive = move([0, 3], [0, 0], [1, 2], [0, 3], [RIGHT, LEFT], lifelong=True,
                  tasks=[4, 3, 0, 0, 0, 0, 0, 0])  # agent 0 reaches (1, 0), then heads for (4, 3)
    assert arrive["reached"].tolist() == [True, False] and not arrive["arrived"].any()
    assert (arrive["gx"][0], arrive["gy"][0], arrive["next_goal"].tolist()) == (4, 3, [1, 0])
    assert arrive["out"][MOVE_EVERYONE] == 0
    done = move([0, 3], [0, 0], [1, 3], [0, 1], [RIGHT, DOWN])
    assert done["out"][MOVE_EVERYONE] == 1 and done["arrived"].all()
    ranks = [UNWANTED_RANK] * 2 * N_ACTIONS
    ranks[0 * N_ACTIONS + RIGHT] = 0  # agent 0 wanted RIGHT first; it was given STAY
    ranks[0 * N_ACTIONS + STAY] = 1
    ranks[1 * N_ACTIONS + STAY] = 0
    refused = move([0, 3], [0, 0], [4, 3], [3, 3], [STAY, STAY], refuse=True, ranks=ranks)
    assert refused["r_ca"].tolist() == [0.0, CA_REWARD]
    assert refused["row_f"][ROW_REWARD_CA] == CA_REWARD
