"""The learner kernel: TD updates (Eq. 9, 10) by hand, the neighbour-state readings, Eq. 6-8,
ties, the random step, the interaction radius, the shield, and the runs it plays."""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from nnql_swarm.learning.fields import (
    FP_FIELDS, LF_FIELDS, LP_FIELDS, LP_KNOWN_STATE, LP_RADIUS, LP_RANDOM_STEP, LP_READING,
    LP_SHIELD, LS_PENDING, LS_TAKEN, NB_FIELDS, READ_DAQL, READ_DIR, READ_NNQL, READ_QL, REC_COUNT,
    REC_PAIRS, RF_FIELDS, UNKNOWN_MOVE, V_CROWD, V_FINAL, VALUES_SIZE, Grid, LearnerBuffers, Sight, ca_rows, record_size,
    state_size,
)
from nnql_swarm.learning.known_map import fresh_map, map_size
from nnql_swarm.learning.learner import choose, decide, finish, make_way, planned_cell
from nnql_swarm.learning.readings import ca_row, shield_mask
from nnql_swarm.learning.record import (
    apply_record, apply_records, record_outcome, write_entries, write_updates,
)
from nnql_swarm.experiment.paper import PaperSettings, RunSpec, run_batch
from nnql_swarm.protocol.actions import DOWN, LEFT, N_ACTIONS, N_STATES, RIGHT, STAY, UP, offset_state
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import plain_python_environment
from nnql_swarm.protocol.messages import pack_updates

NEVER = 10**9
"""A random step so large that no action is random."""
PREFER_STAY = np.array([0.0, 0.1, 0.2, 0.3, 0.9])
"""Tie-breakers under which an all-equal table picks STAY."""
SIZE = 11


def neighbour(j, x, y, next_cell=None, state_cell=None, parked=False, previous=(-1, -1)):
    """A neighbour row: its intent is known where ``next_cell`` is given."""
    known = next_cell is not None
    nx, ny = next_cell if known else (x, y)
    sx, sy = state_cell if state_cell is not None else (nx, ny)
    return [j, x, y, int(known), nx, ny, sx, sy, int(parked), *previous, 0]


class Agent:
    """One learner's buffers, as the swarm simulator holds them, with the kernel's steps."""

    def __init__(self, reading=READ_QL, k=NEVER, alpha=0.9, gamma=0.6, beta=0.5, radius=10,
                 known_state=False, shield=False, neighbours=4):
        self.params = np.zeros(LP_FIELDS, np.int64)
        self.params[[LP_READING, LP_KNOWN_STATE, LP_RADIUS, LP_SHIELD, LP_RANDOM_STEP]] = [
            reading, known_state, radius, shield, k]
        self.params_f = np.array([alpha, gamma, beta, 0.5])
        assert self.params_f.size == FP_FIELDS
        self.q_ds = np.zeros((N_STATES, N_ACTIONS))
        self.q_ca = np.zeros((ca_rows(reading, known_state), N_ACTIONS))
        self.state = np.zeros(state_size(neighbours + 1), np.int64)
        self.state_f = np.zeros(LF_FIELDS)
        self.rec = np.zeros(record_size(neighbours + 1), np.int64)
        self.rec_f = np.zeros(RF_FIELDS)
        self.values = np.zeros(VALUES_SIZE)
        self.wmap = np.zeros(map_size(SIZE, SIZE), np.int64)
        fresh_map(self.wmap)
        self.walls = np.zeros((2, 0), np.int64)  # wall_x, wall_y

    def rows(self, neighbours):
        nb = np.zeros((max(len(neighbours), 1), NB_FIELDS), np.int64)
        if neighbours:
            nb[:len(neighbours)] = neighbours
        return nb, len(neighbours)

    def buffers(self):
        return LearnerBuffers(self.q_ds, self.q_ca, self.params, self.params_f, self.state,
                              self.state_f, self.wmap, self.rec, self.rec_f, self.values)

    def grid(self):
        return Grid(SIZE, SIZE, *self.walls, 0, self.walls.shape[1])

    def decide(self, own, goal, neighbours=(), random_action=UP, ties=PREFER_STAY):
        nb, m = self.rows(neighbours)
        action, _ = decide(self.buffers(), self.grid(), Sight(*own, *goal, nb, m, False),
                           random_action, np.asarray(ties, float), True)
        return action

    def record(self, r_ds, r_ca, arrived=False):
        record_outcome(self.state, self.state_f, r_ds, r_ca, arrived)

    def finish(self, own, goal, neighbours=()):
        nb, m = self.rows(neighbours)
        return finish(self.buffers(), self.grid(), Sight(*own, *goal, nb, m, False), True)

    def row(self, own, nb_row):
        nb, _ = self.rows([nb_row])
        return ca_row(self.params[LP_READING], bool(self.params[LP_KNOWN_STATE]), *own, nb, 0)


def s(dx, dy):
    return offset_state(dx, dy)


def test_apply_record_is_eq_9_then_eq_10_per_neighbour():
    q_ds, q_ca = np.zeros((N_STATES, N_ACTIONS)), np.zeros((N_STATES, N_ACTIONS))
    q_ds[7, RIGHT], q_ds[9] = 0.5, [1.0, 2.0, 3.0, 0.0, -1.0]
    q_ca[3, RIGHT], q_ca[4] = 2.0, [0.0, 5.0, 0.0, 0.0, 0.0]
    rec = np.array([7, RIGHT, 0, 9, 1, 2, 3, 4, 11, -1], np.int64)
    apply_record(q_ds, q_ca, rec, np.array([1.0, 10.0]), 0.9, 0.6)
    assert q_ds[7, RIGHT] == pytest.approx(0.5 + 0.9 * (1.0 + 0.6 * 3.0 - 0.5))
    assert q_ca[3, RIGHT] == pytest.approx(2.0 + 0.9 * (10.0 + 0.6 * 5.0 - 2.0))
    # A neighbour that left view (s' = -1) is not bootstrapped: its interaction ended.
    assert q_ca[11, RIGHT] == pytest.approx(0.9 * 10.0)
    q_ds[7, RIGHT] = 0.5
    rec[2] = 1  # terminal: no future
    apply_record(q_ds, q_ca, rec, np.array([1.0, 10.0]), 0.9, 0.6)
    assert q_ds[7, RIGHT] == pytest.approx(0.5 + 0.9 * (1.0 - 0.5))


_RECORDS = [([7, RIGHT, 0, 9, 1, 2, 3, 4, 11, -1], [1.0, 10.0]),
            ([9, UP, 1, 9, 5, 1, 3, 12], [-0.5, 2.0]),  # Q_CA row 3 again, and blocks of 5
            ([7, RIGHT, 0, 7, 1, 0], [0.25, 0.0])]  # Q_DS row 7 again, no neighbour
_APPLIED_IN_PLAIN_PYTHON = """
import json, sys
import numpy as np
from nnql_swarm.learning.record import apply_records
records, q_ds, q_ca = json.loads(sys.stdin.read())
q_ds, q_ca = np.array(q_ds), np.array(q_ca)
flat = [value for ints, _ in records for value in ints]
starts = [0]
for ints, _ in records:
    starts.append(starts[-1] + len(ints))
written = [0] * len(flat)
n = apply_records(q_ds, q_ca, flat, starts, [floats for _, floats in records], len(records),
                  0.9, 0.6, written)
print(json.dumps([written[:n], q_ds.tolist(), q_ca.tolist()]))
"""


def test_a_ticks_records_are_applied_in_order_in_one_call_compiled_and_in_plain_python():
    """``apply_records``: the records one after the other by ``apply_record``, each entry they
    wrote named in the order they wrote it (both tables stacked, five actions a row): compiled
    over arrays, and in plain Python (a process that runs the kernels uncompiled) over lists."""
    expected_ds, expected_ca = np.zeros((N_STATES, N_ACTIONS)), np.zeros((N_STATES * 5, 5))
    expected_ds[9], expected_ca[4] = [1.0, 2.0, 3.0, 0.0, -1.0], [0.0, 5.0, 0.0, 0.0, 0.0]
    start_ds, start_ca = expected_ds.copy(), expected_ca.copy()
    for ints, floats in _RECORDS:
        apply_record(expected_ds, expected_ca, np.array(ints), np.array(floats), 0.9, 0.6)
    entries = [7 * N_ACTIONS + RIGHT, (N_STATES + 3) * N_ACTIONS + RIGHT,
               (N_STATES + 11) * N_ACTIONS + RIGHT, 9 * N_ACTIONS + UP,
               (N_STATES + 3) * N_ACTIONS + UP, 7 * N_ACTIONS + RIGHT]
    q_ds, q_ca = start_ds.copy(), start_ca.copy()
    flat = np.array([value for ints, _ in _RECORDS for value in ints])
    written = np.zeros(len(flat), dtype=np.int64)
    n = apply_records(q_ds, q_ca, flat, np.array([0, 10, 18, 24]),
                      np.array([floats for _, floats in _RECORDS]), 3, 0.9, 0.6, written)
    assert written[:n].tolist() == entries
    assert q_ds.tolist() == expected_ds.tolist() and q_ca.tolist() == expected_ca.tolist()
    plain = subprocess.run([sys.executable, "-c", _APPLIED_IN_PLAIN_PYTHON],
                           input=json.dumps([_RECORDS, start_ds.tolist(), start_ca.tolist()]),
                           env=plain_python_environment(), capture_output=True, text=True,
                           check=True)
    assert json.loads(plain.stdout) == [entries, expected_ds.tolist(), expected_ca.tolist()]


def test_one_step_updates_both_tables_as_eq_9_and_10():
    agent = Agent()
    assert agent.decide((2, 2), (5, 2), [neighbour(1, 2, 4)]) == STAY
    s_goal, s_nb = s(3, 0), s(0, 2)
    agent.q_ds[s_goal] = [0.0, 0.0, 0.0, 4.0, 1.0]
    agent.q_ca[s_nb, STAY] = 2.0
    agent.q_ca[s(0, 1)] = [0.0, 5.0, 0.0, 0.0, 0.0]
    agent.record(0.1, 10.0)
    agent.decide((2, 2), (5, 2), [neighbour(1, 2, 3)])
    assert agent.q_ds[s_goal, STAY] == pytest.approx(1.0 + 0.9 * (0.1 + 0.6 * 4.0 - 1.0))
    assert agent.q_ca[s_nb, STAY] == pytest.approx(2.0 + 0.9 * (10.0 + 0.6 * 5.0 - 2.0))


def test_arrival_is_terminal_for_destination_seeking():
    agent = Agent()
    agent.q_ds[s(1, 0), RIGHT] = 1.0
    assert agent.decide((4, 2), (5, 2), [neighbour(1, 0, 0)]) == RIGHT
    agent.q_ds[s(0, 0)] = 100.0  # must not be bootstrapped from
    agent.record(10.0, 10.0, arrived=True)
    assert agent.finish((5, 2), (5, 2), [neighbour(1, 0, 0)])
    assert agent.q_ds[s(1, 0), RIGHT] == pytest.approx(1.0 + 0.9 * (10.0 - 1.0))
    assert agent.state[LS_PENDING] == 0 and not agent.finish((5, 2), (5, 2))


def test_only_neighbours_within_the_interaction_radius_enter_eq_6_and_learn():
    agent = Agent(radius=2)
    far, near = neighbour(1, 9, 9), neighbour(2, 5, 7)
    agent.q_ca[s(4, 4)] = [100.0, 0.0, 0.0, 0.0, 0.0]  # would pull towards UP if it counted
    assert agent.decide((5, 5), (0, 0), [far, near]) == STAY
    agent.record(0.0, 10.0)
    agent.decide((5, 5), (0, 0), [far, near])
    assert agent.q_ca[s(0, 2), STAY] == pytest.approx(0.9 * 10.0)
    assert agent.q_ca[s(4, 4)].tolist() == [100.0, 0.0, 0.0, 0.0, 0.0]


def test_readings_of_a_neighbours_state():
    own = (3, 3)
    moving = neighbour(1, 3, 4, next_cell=(3, 5))
    unknown = neighbour(2, 6, 3)
    parked = neighbour(3, 4, 3, parked=True)
    ql, nnql = Agent(READ_QL), Agent(READ_NNQL)
    assert [ql.row(own, r) for r in (moving, unknown, parked)] == [s(0, 1), s(3, 0), s(1, 0)]
    assert [nnql.row(own, r) for r in (moving, unknown, parked)] == [s(0, 2), s(3, 0), s(1, 0)]
    # The direction-aware reading adds the announced move (unknown: a code of its own).
    d = Agent(READ_DIR)
    assert d.q_ca.shape[0] == N_STATES * (N_ACTIONS + 1)
    assert d.row(own, moving) == s(0, 2) + N_STATES * DOWN
    assert d.row(own, unknown) == s(3, 0) + N_STATES * UNKNOWN_MOVE
    # A distinct block for what is known: an arrived neighbour differs from an unknown one.
    known_ql, known_nnql = Agent(READ_QL, known_state=True), Agent(READ_NNQL, known_state=True)
    assert known_ql.q_ca.shape[0] == 2 * N_STATES
    assert [known_ql.row(own, r) for r in (moving, unknown, parked)] == [
        s(0, 1), s(3, 0), s(1, 0) + N_STATES]
    assert [known_nnql.row(own, r) for r in (moving, unknown, parked)] == [
        s(0, 2) + N_STATES, s(3, 0), s(1, 0) + N_STATES]
    assert Agent(READ_DIR, known_state=True).row(own, parked) == s(1, 0) + N_STATES * STAY
    # n-step: the state is read at the cell announced n steps ahead.
    ahead = neighbour(4, 3, 4, next_cell=(3, 5), state_cell=(3, 6))
    assert nnql.row(own, ahead) == s(0, 3)


def test_daql_predicts_the_last_move_and_learns_the_move_seen():
    agent = Agent(READ_DAQL)
    assert agent.q_ca.shape[0] == N_STATES * N_ACTIONS
    walking = neighbour(1, 5, 4, previous=(4, 4))  # it moved RIGHT last tick
    assert agent.row((5, 6), walking) == s(0, -2) + N_STATES * RIGHT
    assert agent.row((5, 6), neighbour(1, 5, 4)) == s(0, -2) + N_STATES * STAY  # unseen before
    agent.q_ca[s(0, -1) + N_STATES * LEFT] = [0.0, 7.0, 0.0, 0.0, 0.0]  # the best pair of s'
    agent.decide((5, 6), (9, 9), [walking])
    agent.record(0.0, 10.0)
    agent.decide((5, 6), (9, 9), [neighbour(1, 5, 5, previous=(5, 4))])  # it moved DOWN
    assert agent.rec[REC_COUNT] == 1
    learned, bootstrap = agent.rec[REC_PAIRS], agent.rec[REC_PAIRS + 1]
    assert learned == s(0, -2) + N_STATES * DOWN and bootstrap == s(0, -1)
    assert agent.q_ca[learned, STAY] == pytest.approx(0.9 * (10.0 + 0.6 * 7.0))


def test_offsets_beyond_the_window_are_clipped_keeping_direction():
    assert s(25, -3) == s(10, -3) and s(-40, 40) == s(-10, 10)


def test_q_final_mixes_eq_6_and_7_with_inverse_distance_weights():
    beta = 0.3
    agent = Agent(beta=beta)
    agent.q_ds[s(2, 0)] = [1, 2, 3, 4, 5]
    agent.q_ca[s(0, 1)] = [10, 0, 0, 0, 0]
    agent.q_ca[s(3, 4)] = [0, 5, 0, 0, 0]
    agent.decide((0, 0), (2, 0), [neighbour(1, 0, 1), neighbour(2, 3, 4)])
    q_ca = np.array([10.0, 5.0 / 5, 0, 0, 0])
    final, crowd = agent.values[V_FINAL:V_FINAL + N_ACTIONS], agent.values[V_CROWD:V_CROWD + N_ACTIONS]
    assert final.tolist() == pytest.approx(beta * np.arange(1, 6) + (1 - beta) * q_ca)
    assert final[0] == beta * 1 + (1 - beta) * (1 / math.sqrt(1) * 10.0)
    assert crowd.tolist() == pytest.approx(q_ca)  # Eq. 6 alone, for the preference order


def test_ties_are_broken_by_the_largest_tie_breaker_among_the_best():
    agent = Agent()
    agent.q_ds[s(5, 5)] = [1.0, 3.0, 3.0, 0.0, 3.0]
    assert agent.decide((0, 0), (5, 5), ties=[0.9, 0.2, 0.7, 0.99, 0.1]) == LEFT


def test_every_kth_action_of_the_learners_lifetime_is_random():
    agent = Agent(READ_NNQL, k=3)
    chosen = []
    for _ in range(2):
        for _ in range(4):  # episodes of 4 actions: the schedule runs on across episodes
            chosen.append(agent.decide((0, 0), (10, 10), [neighbour(1, 9, 0)], random_action=LEFT))
            agent.record(0.0, 0.0)  # zero rewards keep the tables at zero: greedy stays STAY
        agent.finish((0, 0), (10, 10), [neighbour(1, 9, 0)])
    assert chosen == [STAY, STAY, LEFT, STAY, STAY, LEFT, STAY, STAY]
    assert agent.state[LS_TAKEN] == 8


def mask_of(reading, own, neighbours, still=0, escape=0):
    agent = Agent(reading)
    nb, m = agent.rows(neighbours)
    mask = shield_mask(reading, still, escape, *own, nb, m, SIZE, SIZE)
    return {a for a in range(N_ACTIONS) if mask >> a & 1}


def test_the_shield_forbids_announced_cells_swaps_and_parked_agents():
    own = (5, 5)
    assert mask_of(READ_NNQL, own, [neighbour(1, 7, 5, next_cell=(6, 5))]) == {RIGHT}
    assert mask_of(READ_NNQL, own, [neighbour(1, 5, 4, next_cell=(5, 5))]) == {UP, STAY}
    assert mask_of(READ_NNQL, own, [neighbour(1, 4, 5, parked=True)]) == {LEFT}
    assert mask_of(READ_NNQL, own, [neighbour(1, 4, 5)]) == set()  # unknown: not the shield's
    # QL's fair counterpart: the neighbours' current cells.
    assert mask_of(READ_QL, own, [neighbour(1, 4, 5), neighbour(2, 5, 6)]) == {LEFT, DOWN}
    # Nothing allowed: the shield steps aside rather than freeze the agent.
    boxed = [neighbour(1, 5, 4, next_cell=(5, 5)), neighbour(2, 4, 5, parked=True),
             neighbour(3, 6, 5, parked=True), neighbour(4, 5, 6, parked=True)]
    assert mask_of(READ_NNQL, own, boxed) == set()


def test_the_still_shield_takes_a_neighbour_seen_standing_still_as_staying():
    own = (5, 5)
    stood = [neighbour(1, 4, 5, previous=(4, 5))]
    moved = [neighbour(1, 4, 5, previous=(3, 5))]
    unseen = [neighbour(1, 4, 5)]
    assert mask_of(READ_NNQL, own, stood, still=1) == {LEFT}
    assert mask_of(READ_NNQL, own, stood, still=0) == set()
    assert mask_of(READ_NNQL, own, moved, still=1) == set()
    assert mask_of(READ_NNQL, own, unseen, still=1) == set()
    # A known intent outranks the memory: the announced move is what the shield reads.
    leaving = [neighbour(1, 4, 5, next_cell=(3, 5), previous=(4, 5))]
    assert mask_of(READ_NNQL, own, leaving, still=1) == set()


def test_the_escape_shield_pushes_a_neighbour_only_where_it_surely_has_a_way_on():
    own = (5, 5)
    pushed = neighbour(1, 6, 5)  # intent unknown, right of the agent
    # Free cells beyond it, above and below it: it may move on, the push is allowed.
    assert mask_of(READ_NNQL, own, [pushed], escape=1) == set()
    walled = [pushed, neighbour(20, 7, 5), neighbour(21, 6, 4), neighbour(22, 6, 6)]
    assert mask_of(READ_NNQL, own, walled, escape=1) == {RIGHT}
    assert mask_of(READ_NNQL, own, walled, escape=0) == set()
    # Its one empty cell is not sure if a known neighbour announced it...
    announced = [*walled[:3], neighbour(2, 7, 6, next_cell=(6, 6))]
    assert mask_of(READ_NNQL, own, announced, escape=1) == {RIGHT}
    # ... or if another body whose intent is unknown stands next to it, and might step in first;
    contested = [*walled[:3], neighbour(3, 6, 7)]
    assert mask_of(READ_NNQL, own, contested, escape=1) == {RIGHT}
    # a parked agent next to it never moves, and a known one went elsewhere: it is sure.
    parked_by = [*walled[:3], neighbour(3, 6, 7, parked=True), neighbour(4, 5, 6, next_cell=(4, 6))]
    assert mask_of(READ_NNQL, own, parked_by, escape=1) == set()
    # The agent's own cell is no way on (that would be a swap), nor the grid's edge.
    corner = [neighbour(1, 10, 9), neighbour(20, 9, 9), neighbour(21, 10, 8)]
    assert mask_of(READ_NNQL, (10, 10), corner, escape=1) == {UP}
    # A neighbour whose intent is known is read by its announcement, not by its room.
    leaving = [neighbour(1, 6, 5, next_cell=(6, 4)), neighbour(20, 7, 5), neighbour(22, 6, 6)]
    assert mask_of(READ_NNQL, own, leaving, escape=1) == set()


def test_the_shield_filters_greedy_and_random_choices():
    agent = Agent(READ_NNQL, k=1, shield=True)
    parked_right = neighbour(1, 6, 5, parked=True)
    agent.q_ds[s(3, 0)] = [0.0, 0.0, 0.0, 9.0, 1.0]
    assert agent.decide((5, 5), (8, 5), [parked_right], random_action=RIGHT) == STAY
    assert agent.decide((5, 5), (8, 5), [parked_right], random_action=UP) == UP


def test_planned_cell_follows_the_destination_policy_and_stops_on_the_goal():
    q_ds = np.zeros((N_STATES, N_ACTIONS))
    q_ds[s(2, 0), RIGHT] = 1.0
    q_ds[s(1, 0), RIGHT] = 1.0
    assert planned_cell(q_ds, 3, 3, 5, 3, 1, SIZE, SIZE) == (4, 3)
    assert planned_cell(q_ds, 3, 3, 5, 3, 3, SIZE, SIZE) == (5, 3)


def test_k_of_one_is_a_random_walk_for_both_algorithms():
    settings = PaperSettings(episodes=3, max_steps=30)
    both = run_batch([RunSpec("ql", 1, 4), RunSpec("nnql", 1, 4)], settings)
    for name in both.names():
        a, b = getattr(both, name)
        assert np.array_equal(a, b), name


def test_a_batch_gives_exactly_what_each_run_gives_alone():
    settings = PaperSettings(episodes=6, max_steps=40)
    specs = [RunSpec("nnql", 3, 1), RunSpec("ql", 2, 0), RunSpec("nnql", 5, 0), RunSpec("ql", 1, 7)]
    together = run_batch(specs, settings, workers=2)
    for row, spec in enumerate(specs):
        alone = run_batch([spec], settings, workers=1)
        for name in together.names():
            assert np.array_equal(getattr(together, name)[row], getattr(alone, name)[0]), (spec, name)


def test_a_random_step_below_one_is_refused():
    with pytest.raises(ValueError, match="random step"):
        SwarmConfig(random_step=0)


def test_choose_leaves_the_transition_pending_for_the_next_observation():
    agent = Agent()
    nb, m = agent.rows([neighbour(1, 3, 3)])
    choose(agent.buffers(), agent.grid(), Sight(1, 1, 5, 5, nb, m, False), UP, PREFER_STAY)
    assert agent.state[LS_PENDING] == 1
    assert not agent.q_ds.any() and not agent.q_ca.any(), "nothing is learned before s' is seen"


def test_a_learning_record_from_elsewhere_is_checked_against_the_tables():
    from nnql_swarm.learning.record import record_is_valid

    good = (7, RIGHT, 0, 9, 1, 2, 3, 4, 11, -1)
    assert record_is_valid(good, (1.0, 10.0), N_STATES)
    assert record_is_valid((7, RIGHT, 0, 9, 1, 0), (0.0, 0.0), N_STATES)  # no neighbour
    for bad_ints, bad_floats in [
        (good[:-1], (1.0, 10.0)),  # a pair cut short
        ((7, RIGHT, 0, 9, 1, 2, 3, 4, 11, N_STATES), (1.0, 10.0)),  # s' beyond the table
        ((7, RIGHT, 0, 9, 1, 2, N_STATES, 4, 11, -1), (1.0, 10.0)),  # s beyond the table
        ((7, RIGHT, 0, 9, 1, 2, -1, 4, 11, -1), (1.0, 10.0)),  # a negative row would wrap
        ((N_STATES, RIGHT, 0, 9, 1, 0), (1.0, 10.0)), ((7, 5, 0, 9, 1, 0), (1.0, 10.0)),
        ((7, RIGHT, 2, 9, 1, 0), (1.0, 10.0)), ((7, RIGHT, 0, 9, 3, 0), (1.0, 10.0)),
        (good, (math.nan, 10.0)), (good, (1.0,)),
        ((7, RIGHT, 0, 9, N_ACTIONS, 1, 3, N_STATES), (1.0, 10.0)),  # DAQL's blocks overrun
    ]:
        assert not record_is_valid(bad_ints, bad_floats, N_STATES), bad_ints



def way(nb, m, ties):
    """What an agent of 8 learners standing on its goal at (2, 2) of a 5 x 5 grid does."""
    no_walls = np.zeros(0, np.int64)
    return make_way(Sight(2, 2, 2, 2, nb, m, False), 8, Grid(5, 5, no_walls, no_walls, 0, 0),
                    ties)


def test_an_arrived_agent_makes_way_only_for_an_announced_move_into_its_cell():
    ties = np.arange(N_ACTIONS, dtype=float)
    passing = neighbour(0, 2, 1, next_cell=(3, 1))
    assert way(np.array([passing]), 1, ties) == STAY
    pusher = neighbour(0, 2, 1, next_cell=(2, 2))  # from above, into its cell
    wall = neighbour(9, 3, 2, next_cell=(3, 2))
    stranger = neighbour(1, 1, 2)  # a learner whose intent it does not know yet
    # Free cells first (down, the only one), never back into the pusher's cell (a swap)
    assert way(np.array([pusher, wall, stranger]), 3, ties) == DOWN
    below = neighbour(2, 2, 3, next_cell=(2, 3))
    # With no free cell, the unknown learner's cell: its announcement pushes that one on
    assert way(np.array([pusher, wall, stranger, below]), 4, ties) == LEFT
    other_wall = neighbour(10, 1, 2, next_cell=(1, 2))
    assert way(np.array([pusher, wall, other_wall, below]), 4, ties) == STAY


def test_the_shared_tables_updates_are_written_alike_compiled_and_in_plain_python():
    """``write_updates``: compiled, over the payload's arrays, and in plain Python, over lists,
    the same entries written and the same refused: outside the tables, not finite, beyond a
    reward's bounds, or in a group whose values are not as many as its entries."""
    plain = write_entries.__dict__.get("py_func", write_entries)
    [uneven] = pack_updates((5, 6), (1.0, 1.0))
    groups = (pack_updates((3, 9, 4, 12, 7, 8), (0.5, 2.0, math.nan, -7.25, -math.inf, 1e6 + 1))
              + ((uneven[0], uneven[1][:8]),) + pack_updates((1, 3), (-1e6, 1e6)))
    written = []
    for write, arrays in ((write_entries, True), (plain, False)):
        entries = np.zeros(10)
        assert write_updates(entries, groups, write, arrays) == 4 + 2
        written.append(entries)
    assert written[0].tolist() == written[1].tolist() == [
        0.0, -1e6, 0.0, 1e6, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0]
