"""What the learner reads: each neighbour's Q_CA row (``READ_*``), destination seeking's state
and reward (``LP_DS_STATE``, ``LP_DS_REWARD``, on the known map where they read it), and the
actions the announcement shield forbids. Kernel functions (``learning.learner`` has the rules).
"""

from nnql_swarm.learning.fields import (
    DS_GOAL, DS_PROGRESS, FP_STAY_REWARD, LP_DS_REWARD, LP_DS_STATE, LP_KNOWN_STATE, LP_READING,
    NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_PARKED, NB_PREV_X, NB_PREV_Y, NB_ROW, NB_STATE_X,
    NB_STATE_Y, NB_X, NB_Y, READ_DAQL, READ_DIR, READ_QL, REWARD_FLAT, REWARD_WORLD, UNKNOWN_MOVE,
)
from nnql_swarm.learning.known_map import path_length, progress_moves, waypoint_move
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, STAY, move_of, offset_state, target_x, target_y
from nnql_swarm.protocol.jit import kernel

@kernel
def ca_row(reading, known_state, ox, oy, nb, j):
    """The Q_CA row of neighbour row ``j`` for an agent at ``(ox, oy)``."""
    cx = nb[j][NB_X]
    cy = nb[j][NB_Y]
    parked = known_state and nb[j][NB_PARKED] != 0
    if reading == READ_QL:
        return offset_state(cx - ox, cy - oy) + (N_STATES if parked else 0)
    if reading == READ_DAQL:
        return offset_state(cx - ox, cy - oy) + N_STATES * predicted_move(nb, j, parked)
    announced = nb[j][NB_KNOWN] != 0
    if announced or parked:
        if announced:
            state = offset_state(nb[j][NB_STATE_X] - ox, nb[j][NB_STATE_Y] - oy)
            move = move_of(nb[j][NB_NEXT_X] - cx, nb[j][NB_NEXT_Y] - cy)
        else:
            state = offset_state(cx - ox, cy - oy)
            move = STAY
        if reading == READ_DIR:
            return state + N_STATES * move
        return state + (N_STATES if known_state else 0)
    state = offset_state(cx - ox, cy - oy)
    if reading == READ_DIR:
        return state + N_STATES * UNKNOWN_MOVE
    return state


@kernel
def read_rows(params, ox, oy, nb, m):
    """Write each neighbour's Q_CA row (:func:`ca_row`) into its ``NB_ROW``: read once, by the
    completion of the last transition (as ``s'``) and by the choice (as ``s``)."""
    reading = params[LP_READING]
    known_state = params[LP_KNOWN_STATE] != 0
    for j in range(m):
        nb[j][NB_ROW] = ca_row(reading, known_state, ox, oy, nb, j)


@kernel
def predicted_move(nb, j, parked):
    """DAQL's prediction of a neighbour's action: its last move (STAY if parked or unseen)."""
    if parked or nb[j][NB_PREV_X] < 0:
        return STAY
    return move_of(nb[j][NB_X] - nb[j][NB_PREV_X], nb[j][NB_Y] - nb[j][NB_PREV_Y])


@kernel
def uses_map(params):
    """Whether destination seeking reads the known map (``learning.known_map``)."""
    return params[LP_DS_STATE] != DS_GOAL or params[LP_DS_REWARD] != REWARD_WORLD


@kernel
def ds_state(params, wmap, ox, oy, gx, gy, width, height):
    """Destination seeking's state at ``(ox, oy)`` (``LP_DS_STATE``; the map's field current)."""
    reading = params[LP_DS_STATE]
    if reading == DS_GOAL:
        return offset_state(gx - ox, gy - oy)
    if reading == DS_PROGRESS:
        return progress_moves(wmap, ox, oy, width, height)
    move = waypoint_move(wmap, ox, oy, gx, gy, width, height)
    return offset_state(target_x(ox, move, width) - ox, target_y(oy, move, height) - oy)


@kernel
def ds_reward(params, params_f, wmap, fx, fy, ox, oy, width, height, world_reward, arrived):
    """The destination-seeking reward of the move from ``(fx, fy)`` to ``(ox, oy)``
    (``LP_DS_REWARD``): the world's, or read from the path lengths on the known map."""
    kind = params[LP_DS_REWARD]
    if kind == REWARD_WORLD or arrived:
        return world_reward
    before = path_length(wmap, fx, fy, width, height)
    after = path_length(wmap, ox, oy, width, height)
    if after <= 0 or before < 0 or after > before:
        return 0.0
    if after < before:
        return 1.0 if kind == REWARD_FLAT else 1.0 / after
    stay = params_f[FP_STAY_REWARD]
    return stay if kind == REWARD_FLAT else stay / after


@kernel
def shield_mask(reading, still, escape, ox, oy, nb, m, width, height):
    """The actions the announcement shield forbids (:func:`forbids`), as bits (bit ``a`` set:
    ``a`` forbidden); where it would forbid every action, it forbids none."""
    mask = 0
    for a in range(N_ACTIONS):
        if forbids(reading, still, escape, ox, oy, a, nb, m, width, height):
            mask |= 1 << a
    return 0 if mask == (1 << N_ACTIONS) - 1 else mask


@kernel
def forbids(reading, still, escape, ox, oy, a, nb, m, width, height):
    """Whether the announcement shield's rules forbid action ``a`` to the agent at ``(ox, oy)``:
    a move into a cell a known neighbour announced, into a known neighbour's cell when it
    announced moving into this one, or into a parked agent (QL's and DAQL's reading: into any
    neighbour's cell). ``still`` (``LP_STILL_SHIELD``): a neighbour whose intent is unknown and
    that was seen in the same cell last step counts as staying, its cell forbidden like a parked
    agent's; ``escape`` (``LP_ESCAPE_SHIELD``): the cell of a neighbour whose intent is unknown
    is forbidden when that neighbour has no cell it could surely move on to (:func:`cornered`)."""
    tx = target_x(ox, a, width)
    ty = target_y(oy, a, height)
    for j in range(m):
        cx = nb[j][NB_X]
        cy = nb[j][NB_Y]
        if reading == READ_QL or reading == READ_DAQL:
            hit = tx == cx and ty == cy
        elif nb[j][NB_KNOWN] != 0:
            nx = nb[j][NB_NEXT_X]
            ny = nb[j][NB_NEXT_Y]
            hit = (tx == nx and ty == ny) or (nx == ox and ny == oy and tx == cx and ty == cy)
        elif tx != cx or ty != cy:
            hit = False
        else:
            hit = (nb[j][NB_PARKED] != 0
                   or (still != 0 and nb[j][NB_PREV_X] == cx and nb[j][NB_PREV_Y] == cy)
                   or (escape != 0 and cornered(ox, oy, cx, cy, nb, m, width, height)))
        if hit:
            return True
    return False


@kernel
def cornered(ox, oy, cx, cy, nb, m, width, height):
    """Whether the neighbour at ``(cx, cy)``, whose intent the agent at ``(ox, oy)`` does not
    know, has no cell it could surely move on to if pushed: a cell next to it is sure when it is
    on the grid, not the agent's own (that would be a swap), held by no body in the rows, announced
    by no neighbour whose intent is known, and next to no other body whose intent is unknown
    (which might step into it first; a parked agent never moves, and a wall beyond the
    negotiation's reach counts as such a body: the rows do not tell it from an agent). Pushing a
    neighbour only where it has such a cell is priority inheritance one level deep; the
    neighbour, pushed, reads its own neighbours the same way."""
    for a in range(N_ACTIONS):
        if a == STAY:
            continue
        fx = target_x(cx, a, width)
        fy = target_y(cy, a, height)
        if (fx == cx and fy == cy) or (fx == ox and fy == oy):
            continue
        sure = True
        for k in range(m):
            kx = nb[k][NB_X]
            ky = nb[k][NB_Y]
            if nb[k][NB_KNOWN] != 0:
                taken = (kx == fx and ky == fy) or (nb[k][NB_NEXT_X] == fx
                                                    and nb[k][NB_NEXT_Y] == fy)
            else:
                taken = (kx == fx and ky == fy) or (
                    nb[k][NB_PARKED] == 0 and (kx != cx or ky != cy)
                    and abs(kx - fx) + abs(ky - fy) == 1)
            if taken:
                sure = False
                break
        if sure:
            return False
    return True
