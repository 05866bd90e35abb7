"""Where the traffic jams are (``recording.jams``): the steps agents on their way waited, per
cell, and the heat map the recording draws of them."""

import numpy as np

from nnql_swarm.recording.jams import JAM_COLOUR, MAX_ALPHA, MIN_ALPHA, JamMap


def test_only_agents_on_their_way_that_end_a_step_where_they_began_it_count():
    jams = JamMap(4, 3)
    jams.add(((0, 0), (1, 1), (3, 2)), ((0, 0), (2, 1), (3, 2)), (True, True, False))
    jams.add(((0, 0), (2, 1), (3, 2)), ((0, 0), (2, 1), (3, 2)), (True, True, False))
    assert jams.waits.tolist() == [[2, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 0]]
    centres, colours = jams.take()
    assert centres.tolist() == [[2, 1], [0, 0]]  # the most waited on last, drawn on top
    assert colours[:, :3].tolist() == [list(JAM_COLOUR)] * 2
    assert colours[:, 3].tolist() == [MIN_ALPHA, MAX_ALPHA]
    assert not jams.waits.any()  # the next episode starts from nothing


def test_an_episode_without_a_wait_draws_nothing():
    centres, colours = JamMap(3, 3).take()
    assert centres.shape == (0, 2) and colours.shape == (0, 4)
    assert np.asarray(centres).dtype == np.float32
