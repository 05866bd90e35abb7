"""Learning records: the one a learner's pending transition writes (:func:`complete`, Eq. 9's
``s, a, terminal, s'`` and a pair of Q_CA rows per neighbour), the step that applies one
(:func:`apply_record`, Eq. 9 and 10), whether a received one fits the tables, the entries it
writes, and a shared table's updates written into a learner's copy (``learning.learner`` has the
rules; ``learning.fields`` the record's fields).
"""

import math

import numpy as np

from nnql_swarm.learning.fields import (
    DS_GOAL, LF_R_CA, LF_R_DS, LP_DS_STATE, LP_READING, LP_STILL_TERMINAL, LS_ACTION, LS_COUNT,
    LS_GOAL, LS_NEIGHBOURS, LS_PENDING, LS_PER_NEIGHBOUR, LS_TERMINAL, LS_X, LS_Y, NB_ID, NB_ROW,
    NB_X, NB_Y, READ_DAQL, REC_ACTION, REC_BLOCKS, REC_COUNT, REC_GOAL, REC_NEXT_GOAL, REC_PAIRS,
    REC_TERMINAL, RF_FIELDS, RF_R_CA, RF_R_DS,
)
from nnql_swarm.learning.readings import ds_reward, ds_state
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, move_of
from nnql_swarm.protocol.jit import kernel
from nnql_swarm.protocol.messages import MAX_REWARD, unpack_group

def record_is_valid(ints, floats, ca_table_rows: int) -> bool:
    """Whether a learning record received from another agent fits this learner's tables (a
    forged or mistaken record must never write outside them)."""
    if len(ints) < REC_PAIRS or len(floats) != RF_FIELDS:
        return False
    count, blocks = ints[REC_COUNT], ints[REC_BLOCKS]
    if len(ints) != REC_PAIRS + 2 * count or blocks not in (1, N_ACTIONS):
        return False
    if not (0 <= ints[REC_GOAL] < N_STATES and 0 <= ints[REC_NEXT_GOAL] < N_STATES
            and 0 <= ints[REC_ACTION] < N_ACTIONS and ints[REC_TERMINAL] in (0, 1)
            and math.isfinite(floats[0]) and math.isfinite(floats[1])):
        return False
    if count == 0:
        return True
    rows, following = ints[REC_PAIRS::2], ints[REC_PAIRS + 1::2]
    return (min(rows) >= 0 and max(rows) < ca_table_rows and min(following) >= -1
            and max(following) + N_STATES * (blocks - 1) < ca_table_rows)


@kernel
def record_entries_into(rec, out, at):
    """Write the table entries a (valid) learning record writes into ``out`` from ``at`` on, in
    the order :func:`apply_record` writes them; returns where they end. An entry is named by its
    index among both tables stacked, five actions a row: Q_DS's 441 rows, then Q_CA's (how a
    shared table's updates travel)."""
    action = rec[REC_ACTION]
    out[at] = rec[REC_GOAL] * N_ACTIONS + action
    at += 1
    for k in range(rec[REC_COUNT]):
        out[at] = (N_STATES + rec[REC_PAIRS + 2 * k]) * N_ACTIONS + action
        at += 1
    return at


def write_updates(entries: np.ndarray, groups, write, arrays: bool = True) -> int:
    """Write a shared table's updates (groups of packed entry indices and their values,
    ``protocol.messages.Updates``) into a learner's Q-values, both tables flat
    (``learning.tables.Learner.entries``), by ``write`` (:func:`write_entries`, as the process
    runs it: ``learning.ahead``; in plain Python, ``arrays`` False, it reads lists); returns how
    many it refused: every entry of a group whose values are not as many as its entries, and
    those :func:`write_entries` refuses. The world names an entry twice only with the same
    value, its value once the tick's records are all applied (``world.shared_table``), so the
    order does not matter."""
    refused = 0
    for group in groups:
        indices, values = unpack_group(group)
        if len(indices) != len(values):
            refused += max(len(indices), len(values))
        elif arrays:
            refused += write(entries, indices, values, MAX_REWARD)
        else:
            refused += write(entries, indices.tolist(), values.tolist(), MAX_REWARD)
    return refused


@kernel
def write_entries(entries, indices, values, bound):
    """Write ``values[k]`` into ``entries[indices[k]]`` for each k, in order; returns how many it
    refused: those outside the tables, and values not finite or beyond ``bound`` either way."""
    refused = 0
    size = len(entries)
    for k in range(len(indices)):
        entry, value = indices[k], values[k]
        if entry < size and -bound <= value <= bound:  # NaN fails both
            entries[entry] = value
        else:
            refused += 1
    return refused


WRITE_SIGNATURE = ("i8(f8[::1], Array(uint16, 1, 'C', readonly=True), "
                   "Array(float64, 1, 'C', readonly=True), f8)")
""":func:`write_entries`'s types, as compiled ahead of time (``learning.ahead``): the entries and
values as an observation's packed groups hold them (``protocol.messages.unpack_group``:
read-only views of the payload)."""


@kernel
def row_max(table, row):
    """``max_a table[row, a]``."""
    values = table[row]
    best = values[0]
    for a in range(1, N_ACTIONS):
        if values[a] > best:
            best = values[a]
    return best


@kernel
def complete(params, params_f, state, state_f, wmap, ox, oy, gx, gy, nb, m, width, height,
             rec, rec_f):
    """Write the pending transition's learning record, ``s'`` read from this observation
    (own cell, goal, neighbour rows with their ``NB_ROW`` read, the known map current); False if
    nothing was pending."""
    if state[LS_PENDING] == 0:
        return False
    reading = params[LP_READING]
    rec[REC_GOAL] = state[LS_GOAL]
    rec[REC_ACTION] = state[LS_ACTION]
    rec[REC_TERMINAL] = state[LS_TERMINAL]
    rec[REC_NEXT_GOAL] = ds_state(params, wmap, ox, oy, gx, gy, width, height)
    if params[LP_STILL_TERMINAL] != 0:
        if params[LP_DS_STATE] == DS_GOAL:
            still = rec[REC_NEXT_GOAL] == rec[REC_GOAL]
        else:  # a coarse state stays the same along a straight path: ask the cell
            still = ox == state[LS_X] and oy == state[LS_Y]
        if still:
            rec[REC_TERMINAL] = 1
    rec[REC_BLOCKS] = N_ACTIONS if reading == READ_DAQL else 1
    rec_f[RF_R_DS] = ds_reward(params, params_f, wmap, state[LS_X], state[LS_Y], ox, oy, width,
                               height, state_f[LF_R_DS], state[LS_TERMINAL] != 0)
    rec_f[RF_R_CA] = state_f[LF_R_CA]
    count = state[LS_COUNT]
    j = 0  # the pending neighbours and the rows are both in id order: walk them together
    for k in range(count):
        at = LS_NEIGHBOURS + LS_PER_NEIGHBOUR * k
        neighbour, row = state[at], state[at + 1]
        while j < m and nb[j][NB_ID] < neighbour:
            j += 1
        following = -1
        if j < m and nb[j][NB_ID] == neighbour:
            following = nb[j][NB_ROW]
            if reading == READ_DAQL:  # learn the move it made, bootstrap over all moves
                seen = move_of(nb[j][NB_X] - state[at + 2], nb[j][NB_Y] - state[at + 3])
                row = row % N_STATES + N_STATES * seen
                following = following % N_STATES
        rec[REC_PAIRS + 2 * k] = row
        rec[REC_PAIRS + 2 * k + 1] = following
    rec[REC_COUNT] = count
    state[LS_PENDING] = 0
    return True


@kernel
def apply_record(q_ds, q_ca, rec, rec_f, alpha, gamma):
    """Eq. 9, then Eq. 10 once per neighbour in order: ``Q += alpha (r + gamma max Q' - Q)``."""
    action = rec[REC_ACTION]
    values = q_ds[rec[REC_GOAL]]
    current = values[action]
    target = rec_f[RF_R_DS]
    if rec[REC_TERMINAL] == 0:
        target = target + gamma * row_max(q_ds, rec[REC_NEXT_GOAL])
    values[action] = current + alpha * (target - current)
    reward = rec_f[RF_R_CA]
    blocks = rec[REC_BLOCKS]
    for k in range(rec[REC_COUNT]):
        values = q_ca[rec[REC_PAIRS + 2 * k]]
        following = rec[REC_PAIRS + 2 * k + 1]
        current = values[action]
        target = reward
        if following >= 0:
            best = row_max(q_ca, following)
            for block in range(1, blocks):
                best = max(best, row_max(q_ca, following + N_STATES * block))
            target = reward + gamma * best
        values[action] = current + alpha * (target - current)


@kernel
def apply_records(q_ds, q_ca, ints, starts, floats, count, alpha, gamma, written):
    """Apply ``count`` valid records in order (record ``r``: its integers
    ``ints[starts[r]:starts[r + 1]]``, its rewards ``floats[r]``) by :func:`apply_record`, and
    write the entries each one wrote into ``written``, in order; returns how many."""
    at = 0
    for r in range(count):
        rec = ints[starts[r]:starts[r + 1]]
        apply_record(q_ds, q_ca, rec, floats[r], alpha, gamma)
        at = record_entries_into(rec, written, at)
    return at


APPLY_SIGNATURE = "i8(f8[:, ::1], f8[:, ::1], i8[::1], i8[::1], f8[:, ::1], i8, f8, f8, i8[::1])"
""":func:`apply_records`'s types, as compiled ahead of time (``learning.ahead``): the world applies
a tick's records of a shared table with it."""


@kernel
def record_outcome(state, state_f, r_ds, r_ca, arrived):
    """Store the rewards of the last action, and whether it reached the goal (terminal)."""
    state_f[LF_R_DS] = r_ds
    state_f[LF_R_CA] = r_ca
    state[LS_TERMINAL] = 1 if arrived else 0
