"""The learning core: TD updates (Eq. 9, 10) by hand, QL vs nnQL states, weights, ties, exploration."""

import numpy as np
import pytest

from agent.learning import (
    DEFAULT_ALPHA, DEFAULT_GAMMA, Hyper, Learners, View, argmax_ties, goal_state,
    neighbour_states, neighbour_weights, td_update,
)
from launch.paper import PaperSettings, RunSpec, run_batch
from protocol.actions import DOWN, LEFT, N_ACTIONS, N_STATES, RIGHT, STAY, UP, offset_state

NEVER = 10**9
"""A random step so large that no action is random."""


def view(own, goal, nb_cells, nb_next=None, known=None, visible=None) -> View:
    """A batch-of-one view."""
    nb_cells = np.array([nb_cells], dtype=np.int64).reshape(1, -1, 2)
    m = nb_cells.shape[1]
    return View(
        own=np.array([own]),
        goal=np.array([goal]),
        nb_cells=nb_cells,
        nb_next=nb_cells if nb_next is None else np.array([nb_next]).reshape(1, m, 2),
        nb_known=np.ones((1, m), bool) if known is None else np.array([known]),
        nb_visible=np.ones((1, m), bool) if visible is None else np.array([visible]),
    )


def state(dx, dy) -> int:
    return int(offset_state(np.array([dx, dy])))


PREFER_STAY = np.array([[0.0, 0.1, 0.2, 0.3, 0.9]])
"""Tie-breakers under which an all-zero table picks STAY."""


def test_td_update_by_hand():
    table = np.zeros((1, N_STATES, N_ACTIONS))
    table[0, 7, RIGHT] = 0.5
    table[0, 9] = [1.0, 2.0, 3.0, 0.0, -1.0]
    hyper = Hyper(alpha=0.9, gamma=0.6)
    args = dict(rows=np.array([0]), states=np.array([7]), actions=np.array([RIGHT]),
                rewards=np.array([1.0]), next_states=np.array([9]), hyper=hyper)
    td_update(table, bootstrap=np.array([1.0]), **args)
    assert table[0, 7, RIGHT] == pytest.approx(0.5 + 0.9 * (1.0 + 0.6 * 3.0 - 0.5))  # 2.57
    table[0, 7, RIGHT] = 0.5
    td_update(table, bootstrap=np.array([0.0]), **args)
    assert table[0, 7, RIGHT] == pytest.approx(0.5 + 0.9 * (1.0 - 0.5))  # terminal: no future


def test_paper_defaults():
    assert (DEFAULT_ALPHA, DEFAULT_GAMMA) == (0.9, 0.6)


def test_one_step_updates_both_tables_as_eq_9_and_10():
    """Decide, record rewards, decide again: the first transition's updates land by hand."""
    alpha, gamma = 0.9, 0.6
    learners = Learners(np.array([NEVER]), np.array([False]), n_neighbours=1, hyper=Hyper(alpha, gamma, 0.5))
    first = view(own=(2, 2), goal=(5, 2), nb_cells=[(2, 4)])
    action = learners.decide(first, np.array([True]), np.array([UP]), PREFER_STAY)
    assert action.tolist() == [STAY]
    s_goal, s_nb = state(3, 0), state(0, 2)
    # Pre-existing values the update must read: the current entries and the next states' maxima.
    learners.q_ds[0, s_goal, STAY] = 1.0
    learners.q_ca[0, s_nb, STAY] = 2.0
    learners.q_ds[0, s_goal] = [0.0, 0.0, 0.0, 4.0, 1.0]
    learners.q_ca[0, state(0, 1)] = [0.0, 5.0, 0.0, 0.0, 0.0]
    learners.record(r_ds=np.array([0.1]), r_ca=np.array([10.0]), arrived=np.array([False]))
    second = view(own=(2, 2), goal=(5, 2), nb_cells=[(2, 3)])
    learners.decide(second, np.array([True]), np.array([UP]), PREFER_STAY)
    # Eq. 9: s' is the same goal offset, whose max is 4.0 (RIGHT).
    assert learners.q_ds[0, s_goal, STAY] == pytest.approx(1.0 + alpha * (0.1 + gamma * 4.0 - 1.0))
    # Eq. 10: s' is the neighbour's new offset (0, 1), whose max is 5.0.
    assert learners.q_ca[0, s_nb, STAY] == pytest.approx(2.0 + alpha * (10.0 + gamma * 5.0 - 2.0))


def test_arrival_is_terminal_for_destination_seeking():
    learners = Learners(np.array([NEVER]), np.array([False]), n_neighbours=1)
    before = view(own=(4, 2), goal=(5, 2), nb_cells=[(0, 0)])
    learners.q_ds[0, state(1, 0), RIGHT] = 1.0
    action = learners.decide(before, np.array([True]), np.array([UP]), PREFER_STAY)
    assert action.tolist() == [RIGHT]
    learners.q_ds[0, state(0, 0)] = 100.0  # must not be bootstrapped from
    learners.record(np.array([10.0]), np.array([10.0]), arrived=np.array([True]))
    learners.finish(np.array([True]), view(own=(5, 2), goal=(5, 2), nb_cells=[(0, 0)]))
    assert learners.q_ds[0, state(1, 0), RIGHT] == pytest.approx(1.0 + 0.9 * (10.0 - 1.0))


def test_update_repeats_for_each_visible_neighbour_only():
    learners = Learners(np.array([NEVER]), np.array([False]), n_neighbours=2)
    first = view((5, 5), (0, 0), nb_cells=[(5, 6), (9, 9)], visible=[True, False])
    learners.decide(first, np.array([True]), np.array([UP]), PREFER_STAY)
    learners.record(np.array([0.0]), np.array([10.0]), np.array([False]))
    learners.decide(first, np.array([True]), np.array([UP]), PREFER_STAY)
    assert learners.q_ca[0, state(0, 1), STAY] == pytest.approx(0.9 * 10.0)
    assert learners.q_ca[0, state(4, 4), STAY] == 0.0


def test_ql_reads_current_cells_and_nnql_announced_next_cells():
    v = view(own=(3, 3), goal=(0, 0), nb_cells=[(3, 4), (6, 3)], nb_next=[(3, 5), (5, 3)],
             known=[True, False])
    v = View(
        own=np.repeat(v.own, 2, 0), goal=np.repeat(v.goal, 2, 0), nb_cells=np.repeat(v.nb_cells, 2, 0),
        nb_next=np.repeat(v.nb_next, 2, 0), nb_known=np.repeat(v.nb_known, 2, 0),
        nb_visible=np.repeat(v.nb_visible, 2, 0),
    )
    states = neighbour_states(v, use_intents=np.array([False, True]))
    assert states[0].tolist() == [state(0, 1), state(3, 0)]  # QL: where they are
    assert states[1].tolist() == [state(0, 2), state(3, 0)]  # nnQL: where they will be, if known
    assert neighbour_states(v.without_intents(), np.array([True, True]))[1].tolist() == states[0].tolist()
    assert goal_state(v).tolist() == [state(-3, -3)] * 2


def test_offsets_beyond_the_window_are_clipped_keeping_direction():
    assert state(25, -3) == state(10, -3)
    assert state(-40, 40) == state(-10, 10)


def test_neighbour_weights_are_inverse_euclidean_distance_of_visible_neighbours():
    v = view(own=(0, 0), goal=(5, 5), nb_cells=[(1, 2), (3, 4), (0, 1)], visible=[True, True, False])
    assert neighbour_weights(v)[0] == pytest.approx([1 / np.sqrt(5), 1 / 5, 0.0])


def test_q_final_mixes_eq_6_and_7():
    beta = 0.3
    learners = Learners(np.array([NEVER]), np.array([False]), n_neighbours=2, hyper=Hyper(beta=beta))
    v = view(own=(0, 0), goal=(2, 0), nb_cells=[(0, 1), (3, 4)])
    learners.q_ds[0, state(2, 0)] = [1, 2, 3, 4, 5]
    learners.q_ca[0, state(0, 1)] = [10, 0, 0, 0, 0]
    learners.q_ca[0, state(3, 4)] = [0, 5, 0, 0, 0]
    q_ca = np.array([10.0, 5.0 / 5, 0, 0, 0])
    expected = beta * np.array([1, 2, 3, 4, 5]) + (1 - beta) * q_ca
    assert learners.q_final(v)[0] == pytest.approx(expected)


def test_ties_are_broken_by_the_largest_tie_breaker_among_the_best():
    values = np.array([[1.0, 3.0, 3.0, 0.0, 3.0], [2.0, 1.0, 1.0, 1.0, 1.0]])
    breakers = np.array([[0.9, 0.2, 0.7, 0.99, 0.1], [0.0, 0.5, 0.6, 0.7, 0.8]])
    assert argmax_ties(values, breakers).tolist() == [2, 0]


def test_every_kth_action_of_the_learners_lifetime_is_random():
    k = 3
    learners = Learners(np.array([k]), np.array([True]), n_neighbours=1)
    v = view(own=(0, 0), goal=(10, 10), nb_cells=[(9, 0)])
    chosen = []
    for episode in range(2):
        for _ in range(4):  # episodes of 4 actions: the schedule runs on across episodes
            chosen.append(int(learners.decide(v, np.array([True]), np.array([LEFT]), PREFER_STAY)[0]))
            # Zero rewards keep both tables at zero, so the greedy choice stays STAY.
            learners.record(np.array([0.0]), np.array([0.0]), np.array([False]))
        learners.finish(np.array([True]), v)
    assert chosen == [STAY, STAY, LEFT, STAY, STAY, LEFT, STAY, STAY]


def test_inactive_learners_do_not_advance_their_schedule():
    learners = Learners(np.array([2, 2]), np.array([False, False]), n_neighbours=1)
    two = View(
        own=np.array([(0, 0), (0, 0)]), goal=np.array([(5, 5), (5, 5)]),
        nb_cells=np.array([[(9, 9)], [(9, 9)]]), nb_next=np.array([[(9, 9)], [(9, 9)]]),
        nb_known=np.ones((2, 1), bool), nb_visible=np.ones((2, 1), bool),
    )
    ties = np.repeat(PREFER_STAY, 2, 0)
    learners.decide(two, np.array([True, False]), np.array([DOWN, DOWN]), ties)
    assert learners.actions_taken.tolist() == [1, 0]
    second = learners.decide(two, np.array([True, True]), np.array([DOWN, DOWN]), ties)
    assert second.tolist() == [DOWN, STAY]


def test_k_of_one_is_a_random_walk_for_both_algorithms():
    settings = PaperSettings(episodes=3, max_steps=30)
    both = run_batch([RunSpec("ql", 1, 4), RunSpec("nnql", 1, 4)], settings)
    for name in ("steps", "collisions", "reward_ds", "reward_ca", "arrived"):
        a, b = getattr(both, name)
        assert np.array_equal(a, b), name


def test_a_batch_gives_exactly_what_each_run_gives_alone():
    settings = PaperSettings(episodes=6, max_steps=40)
    specs = [RunSpec("nnql", 3, 1), RunSpec("ql", 2, 0), RunSpec("nnql", 5, 0), RunSpec("ql", 1, 7)]
    together = run_batch(specs, settings)
    for row, spec in enumerate(specs):
        alone = run_batch([spec], settings)
        for name in ("steps", "collisions", "reward_ds", "reward_ca", "shortest", "arrived"):
            assert np.array_equal(getattr(together, name)[row], getattr(alone, name)[0]), (spec, name)


def test_learners_reject_a_random_step_below_one():
    with pytest.raises(ValueError):
        Learners(np.array([0]), np.array([False]), n_neighbours=1)


def test_actions_are_the_papers_five():
    assert (UP, DOWN, LEFT, RIGHT, STAY) == (0, 1, 2, 3, 4) and N_ACTIONS == 5 and N_STATES == 441


def test_a_learner_that_sits_out_a_decision_keeps_its_pending_update():
    learners = Learners(np.array([NEVER]), np.array([False]), n_neighbours=1)
    v = view((1, 1), (3, 3), [(5, 5)])
    learners.decide(v, np.array([True]), np.array([0]), np.zeros((1, N_ACTIONS)))
    learners.record(np.array([0.5]), np.array([10.0]), np.array([False]))
    learners.decide(v, np.array([False]), np.array([0]), np.zeros((1, N_ACTIONS)))
    assert not learners.q_ds.any(), "nothing is learned by a learner that sits out"
    learners.decide(v, np.array([True]), np.array([0]), np.zeros((1, N_ACTIONS)))
    assert learners.q_ds.sum() == pytest.approx(DEFAULT_ALPHA * 0.5)
    assert learners.q_ca.sum() == pytest.approx(DEFAULT_ALPHA * 10.0)
