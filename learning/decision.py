"""An agent's whole decision at an observation, as one kernel function over flat buffers.

:func:`agent_decision` is what ``agent.brain.AgentBrain.act`` does with an observation: its
neighbour rows read (``learning.neighbours.neighbour_rows_into``), the rewards of the last action
stored, the pending transition completed, and either the choice (Eq. 6-8, with the announced order
under ``--arbitration pibt``) or, for an agent that stops (arrived, or the episode ended), the order
it offers while it stays. Its arguments are the learner's buffers, the grid's and the sight's fields
one by one, rather than the named tuples of ``learning.fields``, so that it can be compiled ahead of
time with a fixed signature (:data:`SIGNATURE`; ``learning.ahead``): an agent process, which must
not load numba, then makes the whole decision in one compiled call, where in plain Python it is
several dozen small functions. Plain, compiled by numba or ahead of time, it is the same code.
"""

from nnql_swarm.learning.fields import Grid, LearnerBuffers, Sight
from nnql_swarm.learning.learner import announce_order, decide, finish, preference_ranks
from nnql_swarm.learning.neighbours import neighbour_rows_into
from nnql_swarm.learning.record import record_outcome
from nnql_swarm.protocol.actions import STAY
from nnql_swarm.protocol.jit import kernel

OUT_ACTION, OUT_WRITTEN, OUT_ORDERED, OUT_FIELDS = 0, 1, 2, 3
"""The fields of :func:`agent_decision`'s ``outcome``: the action; whether a learning record was
written (``learner.rec``); whether the moves' order was written into ``ranks``."""


@kernel
def agent_decision(q_ds, q_ca, params, params_f, state, state_f, wmap, rec, rec_f, values,
                   width, height, wall_x, wall_y, x, y, goal_x, goal_y, seen, k, reach, keep,
                   parked, p, answer, prev_x, prev_y, was_x, was_y, knows_walls, wall_ids,
                   n_walls, wall_far, radius, meet, nb, starts, reward_ds, reward_ca, arrived,
                   stops, episode_end, pibt, apply_now, random_action, ties, ranks, outcome):
    """Decide at an observation: write its neighbour rows into ``nb``
    (``learning.neighbours.neighbour_rows_into`` of ``seen``'s first ``k`` neighbours and
    ``parked``'s first ``p`` ids, each within ``reach``, as ``learning.rows.NeighbourRows``
    reads them); store the last action's rewards and whether it arrived
    (``learning.record.record_outcome``); then, for an agent that ``stops``, complete its pending
    transition and stay (``learning.learner.finish``), offering under ``pibt`` the order of its
    moves with staying first (``preference_ranks``, unless the ``episode_end``); else complete
    and choose (``decide``, with this step's ``random_action`` and five ``ties``), and under
    ``pibt`` announce the order (``announce_order``), whose first move it takes. The learner's
    record is applied at once if ``apply_now``. Writes :data:`OUT_FIELDS` values into
    ``outcome``."""
    m = neighbour_rows_into(seen, k, reach, reach, keep, parked, p, x, y, reach, answer, prev_x,
                            prev_y, was_x, was_y, knows_walls, wall_ids, n_walls, wall_far, radius,
                            meet, width, height, nb)
    learner = LearnerBuffers(q_ds, q_ca, params, params_f, state, state_f, wmap, rec, rec_f,
                             values)
    grid = Grid(width, height, wall_x, wall_y, 0, len(wall_x))
    sight = Sight(x, y, goal_x, goal_y, nb, m, starts)
    record_outcome(state, state_f, reward_ds, reward_ca, arrived)
    ordered = False
    if stops:
        written = finish(learner, grid, sight, apply_now)
        action = STAY
        if pibt and not episode_end:
            preference_ranks(values, ties, wmap, x, y, width, height, STAY, False, ranks, 0, nb,
                             m)
            ordered = True
    else:
        action, written = decide(learner, grid, sight, random_action, ties, apply_now)
        if pibt:
            action = announce_order(learner, grid, sight, action, ties, ranks, 0)
            ordered = True
    outcome[OUT_ACTION] = action
    outcome[OUT_WRITTEN] = 1 if written else 0
    outcome[OUT_ORDERED] = 1 if ordered else 0


SIGNATURE = ("void(f8[:, ::1], f8[:, ::1], i8[::1], f8[::1], i8[::1], f8[::1], i8[::1], i8[::1], "
             "f8[::1], f8[::1], i8, i8, i8[::1], i8[::1], i8, i8, i8, i8, "
             "i8[:, ::1], i8, i8, i8[::1], i8[::1], i8, i8[::1], i8[::1], i8[::1], i8, i8, b1, "
             "i8[::1], i8, i8, i8, b1, i8[:, ::1], b1, "
             "f8, f8, b1, b1, b1, b1, b1, i8, f8[::1], i8[::1], i8[::1])")
""":func:`agent_decision`'s types, as compiled ahead of time: every buffer a C-contiguous numpy
array (``int64`` or ``float64``), the neighbours seen ``(k, 3)``, the neighbour rows' buffer
``(size, NB_FIELDS)``."""
