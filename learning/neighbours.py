"""The neighbours as a learner reads them at an observation, as rows (``learning.fields.NB_*``):
all of them written by one kernel, :func:`neighbour_rows_into` (the agent's decision runs it,
``learning.decision.agent_decision``, and so does the world's check of a learning record,
``learning.expected.expected_record``; ``learning.rows.NeighbourRows`` elsewhere), each by
:func:`neighbour_row`, which the simulator's ``sim.episode.neighbour_rows`` calls too. Whom an
agent waits for and knows to stay is ``learning.plan``'s."""

from nnql_swarm.learning.fields import (
    NB_ID, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_PARKED, NB_PREV_X, NB_PREV_Y, NB_STATE_X,
    NB_STATE_Y, NB_X, NB_Y,
)
from nnql_swarm.learning.plan import is_parked
from nnql_swarm.protocol.actions import STAY, sees, target_x, target_y
from nnql_swarm.protocol.jit import inline_kernel, kernel
from nnql_swarm.protocol.ranks import in_reach


@inline_kernel
def neighbour_row(row, j, jx, jy, known, action, parked, px, py, width, height):
    """Write body ``j``'s neighbour row (``learning.fields.NB_*``, but ``NB_ROW``): its cell
    ``(jx, jy)``; whether its move this tick is ``known`` and the cell it goes to (by
    ``action``, where known; else its cell), which is also the cell its state reads (the
    simulator's lookahead overwrites that with the cell planned further on); whether it is
    ``parked`` on its goal; and its cell a tick ago ``(px, py)``, ``(-1, -1)`` where the agent's
    cell then did not see it."""
    row[NB_ID] = j
    row[NB_X] = jx
    row[NB_Y] = jy
    if known:
        nx = target_x(jx, action, width)
        ny = target_y(jy, action, height)
    else:
        nx = jx
        ny = jy
    row[NB_KNOWN] = 1 if known else 0
    row[NB_NEXT_X] = nx
    row[NB_NEXT_Y] = ny
    row[NB_STATE_X] = nx
    row[NB_STATE_Y] = ny
    row[NB_PARKED] = 1 if parked else 0
    row[NB_PREV_X] = px
    row[NB_PREV_Y] = py


write_row = getattr(neighbour_row, "py_func", neighbour_row)
""":func:`neighbour_row` as plain Python, on a list row (the simulator's lookahead, tests)."""


@kernel
def neighbour_rows_into(nb, k, limit, wide, keep, parked, p, x, y, far, answer, prev_x, prev_y,
                        was_x, was_y, knows_walls, wall_ids, n_walls, wall_far, radius, meet,
                        width, height, out):
    """Write the learner's neighbour rows of an observation into ``out``; return how many.

    First the neighbours (``nb``'s first ``k`` rows ``(id, x, y)``, in id order) within ``far``
    of the agent's cell ``(x, y)`` and within ``limit``, or within ``wide`` where ``keep[id]``
    is set: each with its announced move where ``answer[id]`` holds one (-1: unknown), parked if
    among ``parked``'s first ``p`` ids, and its cell a tick ago ``(prev_x[id], prev_y[id])``
    (-1: not seen). Then the walls (``wall_ids``: the id of the wall on each cell, ``y * width
    + x``, -1 for none; ``n_walls`` of them) within ``wall_far``, in cell order, each known to
    stay where ``knows_walls`` and it is within the negotiation's reach (``radius``, ``meet``),
    as the simulator reads a scripted obstacle, and seen a tick ago where the agent's cell then
    (``(was_x, was_y)``, -1: none) saw it."""
    m = 0
    near = min(far, limit)
    kept = min(far, wide)
    for i in range(k):
        j = nb[i][0]
        jx = nb[i][1]
        jy = nb[i][2]
        d = max(abs(jx - x), abs(jy - y))
        if d > near and (d > kept or keep[j] == 0):
            continue
        action = answer[j]
        neighbour_row(out[m], j, jx, jy, action >= 0, STAY if action < 0 else action,
                      is_parked(j, parked, p), prev_x[j], prev_y[j], width, height)
        m += 1
    if n_walls > 0:
        for cy in range(max(0, y - wall_far), min(height, y + wall_far + 1)):
            for cx in range(max(0, x - wall_far), min(width, x + wall_far + 1)):
                j = wall_ids[cy * width + cx]
                if j < 0:
                    continue
                seen = was_x >= 0 and sees(was_x, was_y, cx, cy)
                neighbour_row(out[m], j, cx, cy, knows_walls and in_reach(x, y, cx, cy, radius, meet),
                              STAY, False, cx if seen else -1, cy if seen else -1, width, height)
                m += 1
    return m


ROWS_SIGNATURE = ("i8(i8[:, ::1], i8, i8, i8, i8[::1], i8[::1], i8, i8, i8, i8, i8[::1], i8[::1], "
                  "i8[::1], i8, i8, b1, i8[::1], i8, i8, i8, b1, i8, i8, i8[:, ::1])")
""":func:`neighbour_rows_into`'s types, as compiled ahead of time (``learning.ahead``)."""
