"""World rules: every collision case of arbitrate, its invariants over random ticks, the rewards."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from protocol.actions import DOWN, LEFT, MOVES, N_ACTIONS, RIGHT, STAY, UP, intended_cell
from world.rules import (
    CA_REWARD, GOAL_REWARD, arbitrate, arbitrate_one, collision_reward, destination_reward,
    invariant_violations, shortest_steps,
)

WIDTH, HEIGHT = 5, 4


def tick(cells, actions, count_swaps=False, width=WIDTH, height=HEIGHT):
    """One world of the batch: returns (new cells as tuples, collided as bools), after checking
    that the one-world twin agrees."""
    moved, collided = arbitrate(
        np.array([cells]), np.array([actions]), width, height, count_swaps
    )
    result = [tuple(c) for c in moved[0].tolist()], collided[0].tolist()
    assert arbitrate_one(cells, actions, width, height, count_swaps) == result
    return result


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


def test_worlds_of_a_batch_are_independent():
    positions = np.array([[(0, 0), (2, 0)], [(0, 0), (3, 0)]])
    actions = np.array([[RIGHT, LEFT], [RIGHT, LEFT]])
    moved, collided = arbitrate(positions, actions, WIDTH, HEIGHT, count_swaps=False)
    assert moved.tolist() == [[[0, 0], [2, 0]], [[1, 0], [2, 0]]]
    assert collided.tolist() == [[True, True], [False, False]]


@st.composite
def ticks(draw):
    width = draw(st.integers(1, 6))
    height = draw(st.integers(1, 6))
    n = draw(st.integers(1, min(8, width * height)))
    cells = draw(st.lists(st.integers(0, width * height - 1), min_size=n, max_size=n, unique=True))
    positions = np.array([(c % width, c // width) for c in cells], dtype=np.int64)
    actions = np.array(draw(st.lists(st.integers(0, N_ACTIONS - 1), min_size=n, max_size=n)))
    return positions, actions, width, height, draw(st.booleans())


@settings(max_examples=400, deadline=None)
@given(ticks())
def test_invariants_of_a_tick(case):
    positions, actions, width, height, count_swaps = case
    moved, collided = arbitrate(positions[None], actions[None], width, height, count_swaps)
    moved, collided = moved[0], collided[0]
    target = intended_cell(positions, actions, width, height)
    n = len(positions)

    assert len({tuple(c) for c in moved.tolist()}) == n, "two agents share a cell"
    assert np.all((moved >= 0) & (moved < [width, height])), "an agent left the grid"
    # Collided agents stay; the others reach the cell they aimed at.
    assert np.array_equal(moved[collided], positions[collided])
    assert np.array_equal(moved[~collided], target[~collided])
    # Every collision has a cause: the agent was blocked, or someone aimed at its cell.
    for i in np.flatnonzero(collided):
        blocked = not np.array_equal(target[i], positions[i])
        hit = any(np.array_equal(target[j], positions[i]) for j in range(n) if j != i)
        assert blocked or hit
    if count_swaps:
        for i in range(n):
            for j in range(n):
                swapped = (
                    i != j
                    and np.array_equal(moved[i], positions[j])
                    and np.array_equal(moved[j], positions[i])
                )
                assert not swapped, "swap-through while swaps count as collisions"


@settings(max_examples=200, deadline=None)
@given(ticks())
def test_without_swaps_a_tick_equals_the_one_with_swaps_unless_a_swap_is_tried(case):
    positions, actions, width, height, _ = case
    target = intended_cell(positions, actions, width, height)
    n = len(positions)
    tries_swap = any(
        i != j
        and np.array_equal(target[i], positions[j])
        and np.array_equal(target[j], positions[i])
        and not np.array_equal(target[i], positions[i])
        for i in range(n)
        for j in range(n)
    )
    plain = arbitrate(positions[None], actions[None], width, height, False)
    strict = arbitrate(positions[None], actions[None], width, height, True)
    if not tries_swap:
        assert np.array_equal(plain[0], strict[0]) and np.array_equal(plain[1], strict[1])


def test_destination_reward_closer_same_further_arrived():
    goal = np.array([5, 5])
    closer = destination_reward(np.array([5, 0]), np.array([5, 1]), goal)
    assert closer == pytest.approx(1 / 4)
    same = destination_reward(np.array([2, 1]), np.array([2, 1]), goal)
    assert same == pytest.approx(0.5 / 5)
    further = destination_reward(np.array([5, 1]), np.array([5, 0]), goal)
    assert further == 0.0
    assert destination_reward(np.array([5, 4]), goal, goal) == GOAL_REWARD
    assert destination_reward(np.array([5, 4]), goal, goal, goal_reward=3.5) == 3.5


def test_destination_reward_equal_distance_by_exact_integers():
    # (3, 4) and (4, 3) lie at the same distance 5 from the origin: "stayed the same".
    reward = destination_reward(np.array([3, 4]), np.array([4, 3]), np.array([0, 0]))
    assert reward == pytest.approx(0.5 / 5)


def test_destination_reward_is_batched():
    before = np.array([[0, 0], [2, 2], [1, 0]])
    after = np.array([[1, 0], [2, 2], [0, 0]])
    goal = np.array([[2, 0], [0, 2], [2, 0]])
    assert destination_reward(before, after, goal) == pytest.approx([1.0, 0.25, 0.0])


def test_collision_reward():
    assert collision_reward(np.array([False, True])).tolist() == [CA_REWARD, 0.0]


def test_shortest_steps_is_manhattan():
    assert shortest_steps(np.array([[0, 0], [4, 1]]), np.array([[3, 2], [4, 1]])).tolist() == [5, 0]


def test_move_table_matches_action_names():
    assert MOVES[UP].tolist() == [0, -1] and MOVES[DOWN].tolist() == [0, 1]
    assert MOVES[LEFT].tolist() == [-1, 0] and MOVES[RIGHT].tolist() == [1, 0]
    assert MOVES[STAY].tolist() == [0, 0]


def _violations_by_numpy(before, after, count_swaps):
    """The invariants written over arrays, as a reference for the plain-Python check."""
    problems = []
    if len({tuple(c) for c in after.tolist()}) != len(after):
        problems.append("two agents share a cell")
    if count_swaps:
        for i in np.flatnonzero(np.any(before != after, axis=-1)):
            if (np.all(after == before[i], axis=-1) & np.all(before == after[i], axis=-1)).any():
                problems.append(f"agent {i} swapped through another agent")
    return problems


def test_invariant_violations_name_shared_cells_and_swaps():
    before = np.array([[0, 0], [1, 0], [5, 5]])
    assert invariant_violations(before, np.array([[1, 0], [0, 0], [5, 5]]), True) == [
        "agent 0 swapped through another agent", "agent 1 swapped through another agent"]
    assert invariant_violations(before, np.array([[1, 0], [0, 0], [5, 5]]), False) == []
    assert invariant_violations(before, np.array([[0, 1], [0, 1], [5, 5]]), True) == [
        "two agents share a cell"]
    assert invariant_violations(before, np.array([[1, 0], [2, 0], [5, 6]]), True) == []


def test_invariant_violations_agree_with_the_array_definition():
    rng = np.random.default_rng(5)
    for _ in range(2000):
        n = int(rng.integers(2, 7))
        cells = rng.choice(16, size=n, replace=False)
        before = np.stack([cells % 4, cells // 4], axis=-1)
        after = before + rng.integers(-1, 2, size=(n, 2)) * (rng.random((n, 1)) < 0.7)
        for swaps in (True, False):
            assert invariant_violations(before, after, swaps) == _violations_by_numpy(
                before, after, swaps)
