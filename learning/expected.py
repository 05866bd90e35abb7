"""The learning record an agent's transition writes, rebuilt from what the world saw of it: the
world's check of a record (``world.records``) as one kernel function over flat buffers.

:func:`expected_record` reads the agent's neighbour rows at the observation it decided on and at
the next (``learning.neighbours.neighbour_rows_into``, their Q_CA rows by
``learning.readings.read_rows``) as the agent read them had every awaited answer come, and
completes its pending transition (:func:`complete_pending`: ``learning.record.complete``, the
agent's own). Its arguments are plain buffers, so that it is compiled ahead of time with a fixed
signature (:data:`EXPECTED_SIGNATURE`, ``learning.ahead``): the world, which runs the kernels in
plain Python, then checks a record in one call. An intent is an action, -1 where the world did not
hear it; ``awaited`` and ``staying`` are whom the agent waited for and knew to stay
(``learning.plan``); DAQL's memory of the tick before is the neighbours ``mem`` (their first
``mem_k`` rows ``(id, x, y)``) and the agent's own cell then ``(was_x, was_y)``, -1 for none.
"""

from nnql_swarm.learning.fields import (
    LS_ACTION, LS_COUNT, LS_GOAL, LS_NEIGHBOURS, LS_PENDING, LS_PER_NEIGHBOUR, LS_X, LS_Y, NB_ID,
    NB_ROW, NB_X, NB_Y, REC_COUNT, REC_PAIRS, REC_TERMINAL,
)
from nnql_swarm.learning.neighbours import neighbour_rows_into
from nnql_swarm.learning.readings import read_rows
from nnql_swarm.learning.record import complete, record_outcome
from nnql_swarm.protocol.actions import STAY, offset_state
from nnql_swarm.protocol.jit import kernel

E_WRITTEN, E_COMPLETED, E_DECIDED, E_FIELDS = 0, 1, 2, 3
"""The fields of :func:`expected_record`'s ``counts``: how many integers of ``rec`` the record
holds; how many rows of ``completed`` were read at the next observation; and of ``decided`` at the
decision."""


@kernel
def complete_pending(params, params_f, state, state_f, no_map, bx, by, bgx, bgy, action, decided,
                     n_decided, radius, r_ds, r_ca, arrived, ox, oy, ogx, ogy, completed, m,
                     width, height, map_fields, still_terminal, rec, rec_f):
    """``learning.record.complete`` on the transition an agent at ``(bx, by)``, its goal
    ``(bgx, bgy)``, made by ``action``: its pending neighbours are the rows of ``decided`` (its
    first ``n_decided``, with their ``NB_ROW`` read) within ``radius`` (Eq. 6), its outcome the
    rewards and ``arrived``, and ``s'`` is read at ``(ox, oy)``, goal ``(ogx, ogy)``, with the
    rows ``completed`` (the first ``m``). Where destination seeking reads the agent's known map
    (``map_fields``), which the world does not follow, a step that went nowhere is terminal by
    its cell. Returns how many integers of ``rec`` the record holds."""
    state[LS_PENDING] = 1
    state[LS_GOAL] = offset_state(bgx - bx, bgy - by)
    state[LS_ACTION] = action
    state[LS_X] = bx
    state[LS_Y] = by
    count = 0
    for i in range(n_decided):
        cx = decided[i][NB_X]
        cy = decided[i][NB_Y]
        if max(abs(cx - bx), abs(cy - by)) > radius:
            continue
        at = LS_NEIGHBOURS + LS_PER_NEIGHBOUR * count
        state[at] = decided[i][NB_ID]
        state[at + 1] = decided[i][NB_ROW]
        state[at + 2] = cx
        state[at + 3] = cy
        count += 1
    state[LS_COUNT] = count
    record_outcome(state, state_f, r_ds, r_ca, arrived)
    complete(params, params_f, state, state_f, no_map, ox, oy, ogx, ogy, completed, m, width,
             height, rec, rec_f)
    if map_fields:
        still = still_terminal and ox == bx and oy == by
        rec[REC_TERMINAL] = 1 if arrived or still else 0
    return REC_PAIRS + 2 * rec[REC_COUNT]


@kernel
def answers_into(answer, n, stops, intents, awaited, na, staying, ns):
    """The intents an agent decides with, had every awaited answer come, into ``answer`` (-1:
    unknown): none where it ``stops``; else STAY for each of the first ``ns`` of ``staying``,
    and the heard intent of each of the first ``na`` of ``awaited``."""
    for j in range(n):
        answer[j] = -1
    if stops:
        return
    for i in range(ns):
        answer[staying[i]] = STAY
    for i in range(na):
        j = awaited[i]
        if intents[j] >= 0:
            answer[j] = intents[j]


@kernel
def memory_into(prev_x, prev_y, n, mem, mem_k):
    """DAQL's memory of the tick before into ``prev_x``, ``prev_y`` (-1: not seen): the cells of
    the first ``mem_k`` rows of ``mem``."""
    for j in range(n):
        prev_x[j] = -1
        prev_y[j] = -1
    for i in range(mem_k):
        prev_x[mem[i][0]] = mem[i][1]
        prev_y[mem[i][0]] = mem[i][2]


@kernel
def expected_record(params, params_f, state, state_f, no_map, rec, rec_f, width, height, n,
                    radius, far, meet, reads_intents, wall_ids, n_walls, wall_far, map_fields,
                    still_terminal, b_nb, b_k, b_parked, b_p, bx, by, bgx, bgy, action, b_intents,
                    b_awaited, b_na, b_staying, b_ns, b_mem, b_mem_k, b_was_x, b_was_y, decided,
                    n_decided, nb, k, parked, p, ox, oy, ogx, ogy, r_ds, r_ca, arrived, stops,
                    intents, awaited, na, staying, ns, remembers, answer, prev_x, prev_y, keep,
                    completed, counts):
    """The record of an agent's transition from the observation it decided on (``b_*``: its
    neighbours, parked ids, cell and goal; its ``action``; every intent of that tick as the world
    heard them;
    whom it waited for and knew to stay; DAQL's memory of the tick before) to the next (its
    neighbours, parked ids, cell, goal, rewards, whether it ``arrived`` and ``stops``; this
    tick's intents so far; whom it waits for and knows to stay; whether DAQL remembers the
    decision's tick, ``remembers``), had every awaited answer come at both, into ``rec`` and
    ``rec_f``. The rows at the decision are ``decided``'s first ``n_decided`` where known
    already (the last record's completion), else read into it (``n_decided`` < 0); the rows read
    at the next observation, for the next record, go into ``completed``. Writes
    :data:`E_FIELDS` values into ``counts``."""
    announcing = reads_intents
    if n_decided < 0:
        answers_into(answer, n, False, b_intents, b_awaited, b_na, b_staying, b_ns)
        memory_into(prev_x, prev_y, n, b_mem, b_mem_k)
        n_decided = neighbour_rows_into(b_nb, b_k, radius, radius, keep, b_parked, b_p, bx, by,
                                        far, answer, prev_x, prev_y, b_was_x, b_was_y,
                                        announcing, wall_ids, n_walls, wall_far, radius, meet,
                                        width, height, decided)
        read_rows(params, bx, by, decided, n_decided)
    for j in range(n):
        keep[j] = 0
    for i in range(n_decided):
        j = decided[i][NB_ID]
        if j < n and max(abs(decided[i][NB_X] - bx), abs(decided[i][NB_Y] - by)) <= radius:
            keep[j] = 1
    answers_into(answer, n, stops, intents, awaited, na, staying, ns)
    if remembers:
        memory_into(prev_x, prev_y, n, b_nb, b_k)
        was_x = bx
        was_y = by
    else:
        memory_into(prev_x, prev_y, n, b_nb, 0)
        was_x = -1
        was_y = -1
    m = neighbour_rows_into(nb, k, radius, radius + 2, keep, parked, p, ox, oy, far, answer,
                            prev_x, prev_y, was_x, was_y, reads_intents and not stops, wall_ids,
                            n_walls, wall_far, radius, meet, width, height, completed)
    read_rows(params, ox, oy, completed, m)
    counts[E_WRITTEN] = complete_pending(params, params_f, state, state_f, no_map, bx, by, bgx, bgy,
                                         action, decided, n_decided, radius, r_ds, r_ca, arrived,
                                         ox, oy, ogx, ogy, completed, m, width, height,
                                         map_fields, still_terminal, rec, rec_f)
    counts[E_COMPLETED] = m
    counts[E_DECIDED] = n_decided


EXPECTED_SIGNATURE = (
    "void(i8[::1], f8[::1], i8[::1], f8[::1], i8[::1], i8[::1], f8[::1], i8, i8, i8, i8, i8, b1, "
    "b1, i8[::1], i8, i8, b1, b1, "
    "i8[:, ::1], i8, i8[::1], i8, i8, i8, i8, i8, i8, i8[::1], i8[::1], i8, i8[::1], i8, "
    "i8[:, ::1], i8, i8, i8, i8[:, ::1], i8, "
    "i8[:, ::1], i8, i8[::1], i8, i8, i8, i8, i8, f8, f8, b1, b1, i8[::1], i8[::1], i8, i8[::1], "
    "i8, b1, i8[::1], i8[::1], i8[::1], i8[::1], i8[:, ::1], i8[::1])")
""":func:`expected_record`'s types, as compiled ahead of time (``learning.ahead``)."""
