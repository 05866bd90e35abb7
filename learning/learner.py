"""The learner, once: QL, nnQL and their variants, as kernel functions over one learner's buffers.

An agent holds two tables over the 441 egocentric states (``protocol.actions``): ``Q_DS[s_goal]``
seeks the destination, ``Q_CA[s_i]`` avoids neighbours (one table for all neighbours), five
actions each. At every tick it completes the transition it left pending (Eq. 9 and 10, with the
new observation as ``s'``), then chooses (Eq. 6, 7, 8)::

    Q_CA(a)    = sum_i (1 / d_i) Q_CA[s_i, a]     over the neighbours within the interaction radius
    Q_final(a) = beta Q_DS[s_goal, a] + (1 - beta) Q_CA(a)
    a_t        = argmax_a Q_final(a), ties broken by the agent's seeded tie-breakers,

and every ``k``-th action of its life (the paper's "random step") is its seeded random action
(``k`` 0: never, in frozen play).

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
counterpart masks the neighbours' current cells; the random step is filtered too; with
``LP_STILL_SHIELD`` also the cell of a neighbour of unknown intent seen there last step, with
``LP_ESCAPE_SHIELD`` that of one with no cell it could surely move on to), and
``LP_STILL_TERMINAL``: a step that left the agent where it was (it stayed, was blocked, bumped the
edge) does not bootstrap destination seeking from the state it stayed in, so waiting is not
valued like the move it waits for (docs/swarm.md has the evidence of each).

Destination seeking may read the walls the agent has seen (``learning.known_map``, a buffer
``wmap`` per agent, kept for the run): its state (``LP_DS_STATE``: the goal's offset, the paper's;
the next cell of a shortest path on the known map; or the moves that bring the agent nearer on
it), its reward (``LP_DS_REWARD``: the world's Euclidean ``1/d``, the paper's; ``1/d`` with ``d``
the path length; or a flat 1, 0.5, 0 for a path that got shorter, stayed, grew), and a detour
around the agents it saw parked within reach (``LP_DETOUR``). The caller passes the run's walls
with the grid (``learning.fields.Grid``) and whether the observation is an episode's first with
what the agent sees (``learning.fields.Sight``).

Completing a transition writes a *learning record* (``rec``, ``rec_f``; ``learning.record``),
applied by ``apply_record``: at once for an independent learner, or, where a swarm shares one
table, in agent-id order before the next tick: by the simulator to its one table (``sim.episode``),
by the world to its copy (``world.shared_table``), once it has checked that the record is the one
the sender's own transition wrote (``world.records``, with ``learning.readings.read_rows`` and
``learning.record.complete``), and which hands the entries written to every agent's copy
(``learning.record.write_updates``).

Buffers (numpy arrays when compiled, Python lists in an agent process; their fields in
``learning.fields``), one learner's grouped as ``learning.fields.LearnerBuffers``: ``params``
(``LP_*``), ``params_f`` (``FP_*``), the learner's state ``state`` (``LS_*``) and ``state_f``
(``LF_*``); and the neighbour rows ``nb`` (``NB_*``) of a ``Sight``, one per visible neighbour,
in agent-id order (as the world lists them). The tables ``q_ds`` and ``q_ca`` are numpy arrays
either way. This module holds the choice and a tick's learning; the readings
are in ``learning.readings``.
"""

import math

import numpy as np

from nnql_swarm.learning.fields import (
    FP_ALPHA, FP_BETA, FP_GAMMA, LP_DETOUR, LP_WALL_SIGHT, LP_ESCAPE_SHIELD, LP_RADIUS,
    LP_RANDOM_STEP, LP_READING, LP_SHIELD, LP_STILL_SHIELD, LS_ACTION, LS_COUNT, LS_GOAL,
    LS_NEIGHBOURS, LS_PENDING, LS_PER_NEIGHBOUR, LS_TAKEN, LS_X, LS_Y, NB_ID, NB_KNOWN, NB_NEXT_X,
    NB_NEXT_Y, NB_PREV_X, NB_PREV_Y, NB_ROW, NB_X, NB_Y, V_CROWD,
)
from nnql_swarm.learning.known_map import path_length, track
from nnql_swarm.learning.readings import ds_state, read_rows, shield_mask, uses_map
from nnql_swarm.learning.record import apply_record, complete
from nnql_swarm.protocol.actions import N_ACTIONS, STAY, offset_state, target_x, target_y
from nnql_swarm.protocol.jit import inline_kernel, kernel

def draw_noise(rng: np.random.Generator, random_actions: np.ndarray, ties: np.ndarray) -> None:
    """Draw an agent's noise for one episode into its buffers: an exploring action per step
    (``random_actions``, one per step) and five tie-breakers in [0, 1) per step (``ties``,
    ``(steps, 5)``). The order of the draws is part of the determinism contract."""
    random_actions[:] = rng.integers(0, N_ACTIONS, size=random_actions.shape[0], dtype=np.int64)
    rng.random(out=ties)


@inline_kernel
def choose(learner, grid, sight, random_action, ties):
    """Eq. 6-8 (and the random step): the action, with the transition it starts left pending.
    The five actions' sums are spelled out: it is the agent's hot path in plain Python."""
    q_ca, params, params_f, state = learner.q_ca, learner.params, learner.params_f, learner.state
    values, width, height = learner.values, grid.width, grid.height
    ox, oy, nb, m = sight.x, sight.y, sight.nb, sight.m
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
    goal = ds_state(params, learner.wmap, ox, oy, sight.goal_x, sight.goal_y, width,
                    height)
    beta = params_f[FP_BETA]
    rest = 1.0 - beta
    ds = learner.q_ds[goal]
    values[0] = beta * ds[0] + rest * ca0
    values[1] = beta * ds[1] + rest * ca1
    values[2] = beta * ds[2] + rest * ca2
    values[3] = beta * ds[3] + rest * ca3
    values[4] = beta * ds[4] + rest * ca4
    values[V_CROWD] = ca0
    values[V_CROWD + 1] = ca1
    values[V_CROWD + 2] = ca2
    values[V_CROWD + 3] = ca3
    values[V_CROWD + 4] = ca4
    mask = shield_mask(params[LP_READING], params[LP_STILL_SHIELD], params[LP_ESCAPE_SHIELD], ox,
                       oy, nb, m, width, height) \
        if params[LP_SHIELD] != 0 else 0
    greedy = -1  # the best allowed value; among equals, the largest tie-breaker
    for a in range(N_ACTIONS):
        if (mask >> a) & 1 == 0 and (greedy < 0 or values[a] > values[greedy]
                                     or values[a] == values[greedy] and ties[a] > ties[greedy]):
            greedy = a
    state[LS_TAKEN] += 1
    action = greedy
    if params[LP_RANDOM_STEP] > 0 and state[LS_TAKEN] % params[LP_RANDOM_STEP] == 0 \
            and (mask >> random_action) & 1 == 0:
        action = random_action
    state[LS_PENDING] = 1
    state[LS_GOAL] = goal
    state[LS_ACTION] = action
    state[LS_COUNT] = count
    state[LS_X] = ox
    state[LS_Y] = oy
    return action


assert N_ACTIONS == 5, "choose spells out five actions"


@inline_kernel
def observe_map(params, wmap, grid, sight):
    """Where destination seeking reads the known map: the run's walls in view of the agent's
    cell learned, the parked neighbours within reach taken as obstacles for the rest of the
    episode (``LP_DETOUR``; ``sight.starts``: this observation is an episode's first), the
    distance field to the goal made current (``learning.known_map.track``)."""
    if uses_map(params):
        track(wmap, grid.wall_x, grid.wall_y, grid.first, grid.last, sight.x, sight.y,
              sight.goal_x, sight.goal_y, grid.width, grid.height, sight.nb, sight.m,
              params[LP_DETOUR], sight.starts, params[LP_WALL_SIGHT])


@inline_kernel
def decide(learner, grid, sight, random_action, ties, apply_now):
    """Learn the walls in view (:func:`observe_map`), complete the pending transition (its
    record applied at once if ``apply_now``), then choose: :func:`finish`, then :func:`choose`
    (``random_action`` and the five ``ties``: this step's noise). Returns the action and whether
    a record was written."""
    written = finish(learner, grid, sight, apply_now)
    action = choose(learner, grid, sight, random_action, ties)
    return action, written


@inline_kernel
def finish(learner, grid, sight, apply_now):
    """Complete the pending transition of a learner that stops (arrived, or the episode ended);
    its neighbours' rows carry no intent then. Returns whether a record was written."""
    params, params_f, rec, rec_f = learner.params, learner.params_f, learner.rec, learner.rec_f
    observe_map(params, learner.wmap, grid, sight)
    read_rows(params, sight.x, sight.y, sight.nb, sight.m)
    written = complete(params, params_f, learner.state, learner.state_f, learner.wmap, sight.x,
                       sight.y, sight.goal_x, sight.goal_y, sight.nb, sight.m, grid.width,
                       grid.height, rec, rec_f)
    if written and apply_now:
        apply_record(learner.q_ds, learner.q_ca, rec, rec_f, params_f[FP_ALPHA],
                     params_f[FP_GAMMA])
    return written


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


@inline_kernel
def make_way(sight, learners, grid, ties):
    """Under the ``step-aside`` on-target rule, what an agent standing on its goal does: it
    stays, unless a neighbour whose intent it knows announced moving into its cell; then it
    steps to a neighbouring cell, a free one if it can (nobody there, nobody announced heading
    there), else one where a learner whose intent it does not know stands, which the
    announcement pushes on in turn (priority inheritance, in announcement order); among equals
    the largest tie-breaker. With nowhere to go it stays. It learns nothing from the step."""
    ox, oy, nb, m, width, height = sight.x, sight.y, sight.nb, sight.m, grid.width, grid.height
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


UNREACHED = 1 << 30
"""The known-map length of a move off the grid, into a known wall or away from any way to the
goal (:func:`move_length`)."""


@kernel
def move_length(wmap, x, y, a, width, height):
    """The length of the way to the goal, on the known map, from the cell move ``a`` leads to."""
    tx, ty = target_x(x, a, width), target_y(y, a, height)
    if a != STAY and tx == x and ty == y:
        return UNREACHED
    d = path_length(wmap, tx, ty, width, height)
    return UNREACHED if d < 0 else d


@kernel
def hindrance(nb, m, x, y, a, width, height):
    """How many neighbours next to ``(x, y)`` would find the cell move ``a`` leads to in their
    way: a neighbour coming into this agent's cell (its announced move, ``NB_NEXT``, where known;
    else the move it made last, from ``NB_PREV``) would go on straight into it. PIBT's hindrance
    (Okumura and Nagai, 2025) counts the cells that bring a neighbour nearer its goal, which an
    agent does not know; the way a neighbour comes is what the negotiation and the last tick
    tell it."""
    tx, ty = target_x(x, a, width), target_y(y, a, height)
    count = 0
    for k in range(m):
        jx, jy = nb[k][NB_X], nb[k][NB_Y]
        if nb[k][NB_KNOWN] != 0:
            dx, dy = nb[k][NB_NEXT_X] - jx, nb[k][NB_NEXT_Y] - jy
        elif nb[k][NB_PREV_X] >= 0:
            dx, dy = jx - nb[k][NB_PREV_X], jy - nb[k][NB_PREV_Y]
        else:
            continue
        if (dx != 0 or dy != 0) and jx + dx == x and jy + dy == y \
                and tx == x + dx and ty == y + dy:
            count += 1
    return count


@kernel
def preference_ranks(values, ties, wmap, x, y, width, height, first, by_value, ranks, base,
                     nb, m):
    """An agent's order over its moves, announced for priority inheritance (``--arbitration
    pibt``; ``world.pibt.plan`` reads it): the rank of each action into ``ranks[base + a]``.
    Moves come by the length of the way to the goal they leave on the agent's known map
    (:func:`move_length`); among moves as short, the one fewer neighbours coming this way would
    find in their way first (:func:`hindrance`, over the first ``m`` rows of ``nb``): a pushed
    agent steps aside rather than on ahead of its pusher (frozen play on POGEMA's random maps at
    64 agents: sum of costs 0.93 of PIBT-greedy's, against 0.97 without; docs/swarm.md). Then,
    among moves that bring it nearer, by what it has learned of the crowd where ``by_value``:
    their collision-avoidance sums Q_CA(a) (Eq. 6, ``values`` from ``V_CROWD``), which tell
    apart moves that destination seeking, on the known map, cannot (against Q_final, which
    played at PIBT-greedy's cost); else by this step's tie-breakers (``ties``, the larger
    first). How an agent makes way otherwise (staying, stepping aside or back) is left to the
    tie-breakers, which change every step, as PIBT's: learned values are a fixed order there,
    and two agents that make way alike, step after step, trade cells for good (frozen play on
    POGEMA's random maps at 64 agents: CSR 0.71-0.78 with the values there, 0.96 without). The
    first choice is ``first`` if it is not -1 (the random step, or staying on the goal)."""
    here = move_length(wmap, x, y, STAY, width, height)
    for a in range(N_ACTIONS):
        rank = 0
        if a != first:
            rank = 0 if first < 0 else 1
            la = move_length(wmap, x, y, a, width, height)
            ha = hindrance(nb, m, x, y, a, width, height)
            for b in range(N_ACTIONS):
                if b == a or b == first:
                    continue
                lb = move_length(wmap, x, y, b, width, height)
                hb = hindrance(nb, m, x, y, b, width, height) if lb == la else ha
                if lb != la:
                    better = lb < la
                elif hb != ha:
                    better = hb < ha
                elif by_value and la < here and values[V_CROWD + b] != values[V_CROWD + a]:
                    better = values[V_CROWD + b] > values[V_CROWD + a]
                else:
                    better = ties[b] > ties[a] or (ties[b] == ties[a] and b < a)
                if better:
                    rank += 1
        ranks[base + a] = rank


@kernel
def first_choice(ranks, base):
    """The action ranked 0 (:func:`preference_ranks`)."""
    for a in range(N_ACTIONS):
        if ranks[base + a] == 0:
            return a
    return STAY


@kernel
def random_step_taken(params, state):
    """Whether the action just chosen (:func:`choose`) was the random step."""
    return params[LP_RANDOM_STEP] > 0 and state[LS_TAKEN] % params[LP_RANDOM_STEP] == 0


@inline_kernel
def announce_order(learner, grid, sight, action, ties, ranks, base):
    """After :func:`decide`, the order this learner announces under ``--arbitration pibt``
    (:func:`preference_ranks`): its random step first where it took one, else the best by the
    known map and its values; the first choice becomes the pending transition's action (the
    one it learns from). Returns it."""
    first = action if random_step_taken(learner.params, learner.state) else -1
    preference_ranks(learner.values, ties, learner.wmap, sight.x, sight.y, grid.width,
                     grid.height, first, True, ranks, base, sight.nb, sight.m)
    first = first_choice(ranks, base)
    learner.state[LS_ACTION] = first
    return first
