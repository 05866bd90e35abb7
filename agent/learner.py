"""The learner, once: QL, nnQL and their variants, as kernel functions over one learner's buffers.

An agent holds two tables over the 441 egocentric states (``protocol.actions``): ``Q_DS[s_goal]``
seeks the destination, ``Q_CA[s_i]`` avoids neighbours (one table for all neighbours), five
actions each. At every tick it completes the transition it left pending (Eq. 9 and 10, with the
new observation as ``s'``), then chooses (Eq. 6, 7, 8)::

    Q_CA(a)    = sum_i (1 / d_i) Q_CA[s_i, a]     over the neighbours within the interaction radius
    Q_final(a) = beta Q_DS[s_goal, a] + (1 - beta) Q_CA(a)
    a_t        = argmax_a Q_final(a), ties broken by the agent's seeded tie-breakers,

and every ``k``-th action of its life (the paper's "random step") is its seeded random action.

The readings of a neighbour's state ``s_i`` (``READ_*``; docs/paper.md has the evidence):

- ``READ_QL``: the neighbour's current offset (QL cannot know its move).
- ``READ_NNQL``: the offset of the cell it announced it is heading for, where its intent is known
  (it outranks this agent and is one it waits for: ``protocol.ranks.waits_for``), else its
  current offset (the paper's nnQL, n = 1).
- ``READ_DIR``: nnQL's offset and the announced move (6 codes: 5 moves, unknown), so that a
  neighbour stepping in from the left differs from one coming from the right: a swap can be seen.
- ``READ_DAQL``: Double Action Q-learning (Ngai and Yung; the paper's Eq. 2): the current offset
  and the neighbour's action, predicted at the decision as its last move (STAY when unknown),
  learned with the move it was then seen to make; ``s'`` bootstraps from the best pair of actions.

Options beyond the paper, each one field of the parameters (``LP_*``): the interaction radius
(only neighbours within it, Chebyshev, enter Eq. 6 and get Eq. 10; the paper's reading is the
whole view, 10), a distinct state block for a neighbour known to stay or whose intent is known
(``LP_KNOWN_STATE``: a parked agent then differs from one whose intent is unknown), and the
announcement shield (``LP_SHIELD``: never move into a cell a known neighbour announced, into a known
neighbour's cell when it announced moving into this one, or into a parked agent; QL's fair
counterpart masks the neighbours' current cells; the random step is filtered too), and
``LP_STILL_TERMINAL``: a step that left the agent where it was (it stayed, was blocked, bumped the
edge) does not bootstrap destination seeking from the state it stayed in, so waiting is not
valued like the move it waits for (docs/swarm.md has the evidence of each).

Destination seeking may read the walls the agent has seen (``agent.known_map``, a buffer
``wmap`` per agent, kept for the run): its state (``LP_DS_STATE``: the goal's offset, the paper's;
the next cell of a shortest path on the known map; or the moves that bring the agent nearer on
it), its reward (``LP_DS_REWARD``: the world's Euclidean ``1/d``, the paper's; ``1/d`` with ``d``
the path length; or a flat 1, 0.5, 0 for a path that got shorter, stayed, grew), and a detour
around the agents it saw parked within reach (``LP_DETOUR``). The caller passes the run's walls
(``wall_x``, ``wall_y``, ``first .. last - 1``, in cell order) and whether the observation is
an episode's first (``starts``).

Completing a transition writes a *learning record* (``rec``, ``rec_f``), applied by
:func:`apply_record`: at once for an independent learner, or, where a swarm shares one table, in
agent-id order before the next tick: by the simulator to its one table (``sim.swarm``), by the
world to its copy (``world.shared_table``), once it has checked that the record is the one the
sender's own transition wrote (``world.records``, with :func:`read_rows` and :func:`complete`),
and which hands the entries written to every agent's copy (:func:`write_updates`).

Buffers (numpy arrays when compiled, Python lists in an agent process): ``params`` (``LP_*``),
``params_f`` (``FP_*``), the learner's state ``state`` (``LS_*``) and ``state_f`` (``LF_*``), and
the neighbour rows ``nb`` (``NB_*``), one per visible neighbour, in agent-id order (as the world
lists them). The tables ``q_ds`` and ``q_ca`` are numpy arrays either way.
"""

import math

import numpy as np

from nnql_swarm.agent.known_map import path_length, progress_moves, track, waypoint_move
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, STAY, move_of, offset_state, target_x, target_y
from nnql_swarm.protocol.jit import kernel

READ_QL, READ_NNQL, READ_DIR, READ_DAQL = 0, 1, 2, 3
READINGS = {"ql": READ_QL, "nnql": READ_NNQL, "nnql-dir": READ_DIR, "daql": READ_DAQL}
"""The learning algorithms by name, and the neighbour-state reading each uses."""

UNKNOWN_MOVE = N_ACTIONS
"""The move code of a neighbour whose intent is unknown (``READ_DIR``)."""

LP_READING, LP_KNOWN_STATE, LP_RADIUS, LP_SHIELD, LP_RANDOM_STEP = 0, 1, 2, 3, 4
LP_STILL_TERMINAL, LP_MEET_ONLY, LP_DS_STATE, LP_DS_REWARD, LP_DETOUR = 5, 6, 7, 8, 9
LP_FIELDS = 10
FP_ALPHA, FP_GAMMA, FP_BETA, FP_STAY_REWARD = 0, 1, 2, 3
FP_FIELDS = 4

DS_GOAL, DS_WAYPOINT, DS_PROGRESS = 0, 1, 2
DS_STATES = {"goal": DS_GOAL, "waypoint": DS_WAYPOINT, "progress": DS_PROGRESS}
"""Destination seeking's state (``LP_DS_STATE``): the goal's offset (the paper's); the offset of
the next cell of a shortest path on the agent's known map (``agent.known_map``), one of the four
cells next to it; or the set of moves that bring it nearer on that map (4 bits, 15 states)."""

REWARD_WORLD, REWARD_PATH, REWARD_FLAT = 0, 1, 2
DS_REWARDS = {"euclid": REWARD_WORLD, "path": REWARD_PATH, "flat": REWARD_FLAT}
"""Destination seeking's reward (``LP_DS_REWARD``): the world's (the paper's ``1/d``, ``0.5/d``,
0 with ``d`` the Euclidean distance); the same with ``d`` the path length on the known map; or a
flat progress reward on that map, 1 nearer, the stay reward (0.5) for the same length, 0 farther.
The goal reward on arriving is the world's in every case."""

NB_ID, NB_X, NB_Y, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_STATE_X, NB_STATE_Y = 0, 1, 2, 3, 4, 5, 6, 7
NB_PARKED, NB_PREV_X, NB_PREV_Y, NB_ROW = 8, 9, 10, 11
NB_FIELDS = 12
"""A neighbour row: id, cell, whether its intent is known, the cell it announced it is heading
for (its cell where unknown), the cell its state is read at (the announced cell n steps ahead;
the next cell for n = 1), whether it is parked on its goal, its cell a tick ago (-1 if unseen);
and its Q_CA row, which :func:`read_rows` writes for the steps that read it."""
assert (NB_X, NB_Y, NB_PARKED) == (1, 2, 8), "agent.known_map.see_parked reads them by number"

LS_TAKEN, LS_PENDING, LS_GOAL, LS_ACTION, LS_TERMINAL, LS_COUNT, LS_X, LS_Y = 0, 1, 2, 3, 4, 5, 6, 7
LS_NEIGHBOURS = 8
LS_PER_NEIGHBOUR = 4
"""A learner's state: actions taken in its life, whether a transition is pending, its
destination-seeking state, action and whether it ended on the goal, the cell it decided in, and
per neighbour of Eq. 6: id, table row, cell."""
LF_R_DS, LF_R_CA = 0, 1
LF_FIELDS = 2

REC_GOAL, REC_ACTION, REC_TERMINAL, REC_NEXT_GOAL, REC_BLOCKS, REC_COUNT = 0, 1, 2, 3, 4, 5
REC_PAIRS = 6
RF_R_DS, RF_R_CA = 0, 1
RF_FIELDS = 2
"""A learning record: Eq. 9's ``s, a, terminal, s'`` (destination seeking's states, as
``LP_DS_STATE`` reads them), the blocks ``s'`` bootstraps over, and per neighbour a pair of Q_CA
rows ``(s_i, s'_i)`` (``s'_i`` -1: it left view, no bootstrap); its floats are the two rewards
(destination seeking's as ``LP_DS_REWARD`` reads it: the world's, or the learner's own from its
known map)."""


def learner_params(config) -> tuple[list[int], list[float]]:
    """A learner's ``params`` and ``params_f`` for a run's options (a ``SwarmConfig``; the
    oracle, which learns nothing, reads as QL)."""
    params = [0] * LP_FIELDS
    params[LP_READING] = READINGS.get(config.algo, READ_QL)
    params[LP_KNOWN_STATE] = int(config.known_state)
    params[LP_RADIUS] = config.interaction_radius
    params[LP_SHIELD] = int(config.shield)
    params[LP_RANDOM_STEP] = config.random_step
    params[LP_STILL_TERMINAL] = int(config.still_terminal)
    params[LP_MEET_ONLY] = int(config.meet_only)
    params[LP_DS_STATE] = DS_STATES[config.ds_state]
    params[LP_DS_REWARD] = DS_REWARDS[config.ds_reward]
    params[LP_DETOUR] = reach(config.interaction_radius) if config.detour else -1
    params_f = [0.0] * FP_FIELDS
    params_f[FP_ALPHA], params_f[FP_GAMMA] = config.alpha, config.gamma
    params_f[FP_BETA] = config.beta
    params_f[FP_STAY_REWARD] = config.stay_reward
    return params, params_f


SHIELD_REACH = 2
"""The announcement shield looks this far (Chebyshev): a neighbour farther away can be in none of
the cells it forbids, each within one move of a cell next to this agent."""


def reach(radius: int) -> int:
    """The farthest (Chebyshev) a neighbour can matter to a learner of interaction radius
    ``radius``: within the radius it enters Eq. 6; within two more, it can be one that entered a
    pending transition a tick ago (both moved one cell at most) and so its ``s'``; within
    :data:`SHIELD_REACH` it enters the shield. A neighbour beyond changes nothing the learner
    computes, so an agent may leave it out of the rows it builds (after lost ticks, a neighbour
    of a pending transition that far is read as out of view)."""
    return max(radius + 2, SHIELD_REACH)


def draw_noise(rng: np.random.Generator, random_actions: np.ndarray, ties: np.ndarray) -> None:
    """Draw an agent's noise for one episode into its buffers: an exploring action per step
    (``random_actions``, one per step) and five tie-breakers in [0, 1) per step (``ties``,
    ``(steps, 5)``). The order of the draws is part of the determinism contract."""
    random_actions[:] = rng.integers(0, N_ACTIONS, size=random_actions.shape[0], dtype=np.int64)
    rng.random(out=ties)


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


def record_entries(ints) -> list[int]:
    """The table entries a (valid) learning record writes, in the order :func:`apply_record`
    writes them. An entry is named by its index among both tables stacked, five actions a row:
    Q_DS's 441 rows, then Q_CA's (how a shared table's updates travel)."""
    action = ints[REC_ACTION]
    entries = [ints[REC_GOAL] * N_ACTIONS + action]
    for k in range(ints[REC_COUNT]):
        entries.append((N_STATES + ints[REC_PAIRS + 2 * k]) * N_ACTIONS + action)
    return entries


def write_updates(entries: np.ndarray, groups) -> int:
    """Write a shared table's updates (groups of entry indices and their values,
    ``protocol.messages.Updates``) into a learner's Q-values, both tables flat
    (``agent.brain.Learner.entries``); returns how many it refused: those outside its tables,
    and every entry of a group whose values are not as many as its entries."""
    end = len(entries)
    refused = 0
    for indices, values in groups:
        if len(indices) != len(values):
            refused += max(len(indices), len(values))
            continue
        for index, value in zip(indices, values):
            if index < end:
                entries[index] = value
            else:
                refused += 1
    return refused


def state_size(max_neighbours: int) -> int:
    return LS_NEIGHBOURS + LS_PER_NEIGHBOUR * max_neighbours


def record_size(max_neighbours: int) -> int:
    return REC_PAIRS + 2 * max_neighbours


def ca_rows(reading: int, known_state: bool) -> int:
    """The number of rows of Q_CA for a reading."""
    if reading == READ_DIR:
        return N_STATES * (N_ACTIONS + 1)
    if reading == READ_DAQL:
        return N_STATES * N_ACTIONS
    return N_STATES * (2 if known_state else 1)


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
def row_max(table, row):
    """``max_a table[row, a]``."""
    values = table[row]
    best = values[0]
    for a in range(1, N_ACTIONS):
        if values[a] > best:
            best = values[a]
    return best


@kernel
def uses_map(params):
    """Whether destination seeking reads the known map (``agent.known_map``)."""
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
def shield_mask(reading, ox, oy, nb, m, width, height):
    """The actions the announcement shield forbids, as bits (bit ``a`` set: ``a`` forbidden)."""
    mask = 0
    for a in range(N_ACTIONS):
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
            else:
                hit = nb[j][NB_PARKED] != 0 and tx == cx and ty == cy
            if hit:
                mask |= 1 << a
                break
    return 0 if mask == (1 << N_ACTIONS) - 1 else mask


@kernel
def choose(q_ds, q_ca, params, params_f, state, wmap, ox, oy, gx, gy, nb, m, width, height,
           random_action, ties, values):
    """Eq. 6-8 (and the random step): the action, with the transition it starts left pending.
    The five actions' sums are spelled out: it is the agent's hot path in plain Python."""
    radius = params[LP_RADIUS]
    ca0 = ca1 = ca2 = ca3 = ca4 = 0.0
    count = 0
    for j in range(m):
        dx = nb[j][NB_X] - ox
        dy = nb[j][NB_Y] - oy
        if max(abs(dx), abs(dy)) > radius:
            continue
        weight = 1.0 / max(math.sqrt(dx * dx + dy * dy), 1.0)
        row = nb[j][NB_ROW]
        q = q_ca[row]
        ca0 += weight * q[0]
        ca1 += weight * q[1]
        ca2 += weight * q[2]
        ca3 += weight * q[3]
        ca4 += weight * q[4]
        at = LS_NEIGHBOURS + LS_PER_NEIGHBOUR * count
        state[at] = nb[j][NB_ID]
        state[at + 1] = row
        state[at + 2] = nb[j][NB_X]
        state[at + 3] = nb[j][NB_Y]
        count += 1
    goal = ds_state(params, wmap, ox, oy, gx, gy, width, height)
    beta = params_f[FP_BETA]
    rest = 1.0 - beta
    ds = q_ds[goal]
    values[0] = beta * ds[0] + rest * ca0
    values[1] = beta * ds[1] + rest * ca1
    values[2] = beta * ds[2] + rest * ca2
    values[3] = beta * ds[3] + rest * ca3
    values[4] = beta * ds[4] + rest * ca4
    mask = shield_mask(params[LP_READING], ox, oy, nb, m, width, height) \
        if params[LP_SHIELD] != 0 else 0
    greedy = -1  # the best allowed value; among equals, the largest tie-breaker
    for a in range(N_ACTIONS):
        if (mask >> a) & 1 == 0 and (greedy < 0 or values[a] > values[greedy]
                                     or values[a] == values[greedy] and ties[a] > ties[greedy]):
            greedy = a
    state[LS_TAKEN] += 1
    action = greedy
    if state[LS_TAKEN] % params[LP_RANDOM_STEP] == 0 and (mask >> random_action) & 1 == 0:
        action = random_action
    state[LS_PENDING] = 1
    state[LS_GOAL] = goal
    state[LS_ACTION] = action
    state[LS_COUNT] = count
    state[LS_X] = ox
    state[LS_Y] = oy
    return action


assert N_ACTIONS == 5, "choose spells out five actions"


@kernel
def observe_map(params, wmap, wall_x, wall_y, first, last, ox, oy, gx, gy, width, height, nb,
                m, starts):
    """Where destination seeking reads the known map: the walls ``first .. last - 1`` of
    ``wall_x``, ``wall_y`` in view of ``(ox, oy)`` learned, the parked neighbours within reach
    taken as obstacles for the rest of the episode (``LP_DETOUR``; ``starts``: this observation
    is an episode's first), the distance field to the goal made current
    (``agent.known_map.track``)."""
    if uses_map(params):
        track(wmap, wall_x, wall_y, first, last, ox, oy, gx, gy, width, height, nb, m,
              params[LP_DETOUR], starts)


@kernel
def decide(q_ds, q_ca, params, params_f, state, state_f, wmap, wall_x, wall_y, first, last,
           starts, ox, oy, gx, gy, nb, m, width, height, random_action, ties, values, rec, rec_f,
           apply_now):
    """Learn the walls in view (:func:`observe_map`; ``starts``: the episode's first
    observation), complete the pending transition (its record applied at once if
    ``apply_now``), then choose. Returns the action and whether a record was written."""
    observe_map(params, wmap, wall_x, wall_y, first, last, ox, oy, gx, gy, width, height, nb, m,
                starts)
    read_rows(params, ox, oy, nb, m)
    written = complete(params, params_f, state, state_f, wmap, ox, oy, gx, gy, nb, m, width,
                       height, rec, rec_f)
    if written and apply_now:
        apply_record(q_ds, q_ca, rec, rec_f, params_f[FP_ALPHA], params_f[FP_GAMMA])
    action = choose(q_ds, q_ca, params, params_f, state, wmap, ox, oy, gx, gy, nb, m, width,
                    height, random_action, ties, values)
    return action, written


@kernel
def finish(q_ds, q_ca, params, params_f, state, state_f, wmap, wall_x, wall_y, first, last,
           starts, ox, oy, gx, gy, nb, m, width, height, rec, rec_f, apply_now):
    """Complete the pending transition of a learner that stops (arrived, or the episode ended);
    its neighbours' rows carry no intent then. Returns whether a record was written."""
    observe_map(params, wmap, wall_x, wall_y, first, last, ox, oy, gx, gy, width, height, nb, m,
                starts)
    read_rows(params, ox, oy, nb, m)
    written = complete(params, params_f, state, state_f, wmap, ox, oy, gx, gy, nb, m, width,
                       height, rec, rec_f)
    if written and apply_now:
        apply_record(q_ds, q_ca, rec, rec_f, params_f[FP_ALPHA], params_f[FP_GAMMA])
    return written


@kernel
def make_way(ox, oy, nb, m, learners, width, height, ties):
    """Under the ``step-aside`` on-target rule, what an agent standing on its goal does: it
    stays, unless a neighbour whose intent it knows announced moving into its cell; then it
    steps to a neighbouring cell, a free one if it can (nobody there, nobody announced heading
    there), else one where a learner whose intent it does not know stands, which the
    announcement pushes on in turn (priority inheritance, in announcement order); among equals
    the largest tie-breaker. With nowhere to go it stays. It learns nothing from the step."""
    pushed = False
    for j in range(m):
        if nb[j][NB_KNOWN] != 0 and nb[j][NB_NEXT_X] == ox and nb[j][NB_NEXT_Y] == oy:
            pushed = True
    if not pushed:
        return STAY
    best, best_score = STAY, 0
    for a in range(N_ACTIONS):
        tx = target_x(ox, a, width)
        ty = target_y(oy, a, height)
        if tx == ox and ty == oy:
            continue
        score = 2
        for j in range(m):
            known = nb[j][NB_KNOWN] != 0
            nx, ny = nb[j][NB_NEXT_X], nb[j][NB_NEXT_Y]
            if known and nx == tx and ny == ty:
                score = 0  # announced: taken
            elif nb[j][NB_X] == tx and nb[j][NB_Y] == ty:
                if known:  # it leaves, but into this cell it would be a swap
                    if nx == ox and ny == oy:
                        score = 0
                elif nb[j][NB_ID] < learners:
                    score = min(score, 1)
                else:
                    score = 0
            if score == 0:
                break
        if score > best_score or (score == best_score and score > 0 and ties[a] > ties[best]):
            best, best_score = a, score
    return best


@kernel
def record_outcome(state, state_f, r_ds, r_ca, arrived):
    """Store the rewards of the last action, and whether it reached the goal (terminal)."""
    state_f[LF_R_DS] = r_ds
    state_f[LF_R_CA] = r_ca
    state[LS_TERMINAL] = 1 if arrived else 0


@kernel
def planned_cell(q_ds, x, y, gx, gy, steps, width, height):
    """Where this agent expects to be ``steps`` moves after ``(x, y)``, following its
    destination-seeking policy greedily (first best action; it stops on its goal): the cells an
    n-step announcement carries beyond the binding first move."""
    for _ in range(steps):
        if x == gx and y == gy:
            break
        action = 0
        values = q_ds[offset_state(gx - x, gy - y)]
        for a in range(1, N_ACTIONS):
            if values[a] > values[action]:
                action = a
        nx = target_x(x, action, width)
        y = target_y(y, action, height)
        x = nx
    return x, y
