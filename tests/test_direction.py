"""The direction-aware neighbour state (beyond the paper): it tells apart what nnQL's cannot."""

import numpy as np

from agent.learning import DIRECTION_STATES, UNKNOWN_MOVE, Learners, View, neighbour_states
from protocol.actions import LEFT, N_STATES, RIGHT, offset_state


def view(neighbour_cell, neighbour_next, known=True) -> View:
    return View(
        own=np.array([[5, 5]]), goal=np.array([[9, 9]]),
        nb_cells=np.array([[neighbour_cell]]), nb_next=np.array([[neighbour_next]]),
        nb_known=np.array([[known]]), nb_visible=np.array([[True]]),
    )


def states(v: View, direction: bool) -> int:
    return int(neighbour_states(v, np.array([True]), np.array([direction]))[0, 0])


def test_two_neighbours_stepping_into_my_cell_from_opposite_sides():
    from_right = view((6, 5), (5, 5))  # announces LEFT
    from_left = view((4, 5), (5, 5))  # announces RIGHT
    assert states(from_right, False) == states(from_left, False) == offset_state(np.array([0, 0]))
    assert states(from_right, True) == offset_state(np.array([0, 0])) + N_STATES * LEFT
    assert states(from_left, True) == offset_state(np.array([0, 0])) + N_STATES * RIGHT


def test_an_unknown_announcement_reads_the_current_cell_with_the_unknown_code():
    unknown = view((6, 5), (0, 0), known=False)
    assert states(unknown, True) == offset_state(np.array([1, 0])) + N_STATES * UNKNOWN_MOVE
    assert states(unknown, False) == offset_state(np.array([1, 0]))


def test_only_direction_aware_learners_get_the_larger_table():
    plain = Learners(np.array([5]), np.array([True]), n_neighbours=2)
    aware = Learners(np.array([5]), np.array([True]), n_neighbours=2, with_direction=np.array([True]))
    assert plain.q_ca.shape == (1, N_STATES, 5)
    assert aware.q_ca.shape == (1, DIRECTION_STATES, 5)
