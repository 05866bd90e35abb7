"""The learner's buffers, field by field, and its parameters for a run's options.

Every buffer of the learner's kernel (``learning.learner``) is a flat array or list whose fields
are named here, as are the named tuples its arguments come in (:class:`LearnerBuffers`,
:class:`Grid`, :class:`Sight`): ``params`` (``LP_*``) and ``params_f`` (``FP_*``), the learner's
state ``state`` (``LS_*``) and ``state_f`` (``LF_*``), a neighbour row ``nb[j]`` (``NB_*``), and a learning
record ``rec`` (``REC_*``) and ``rec_f`` (``RF_*``); with the readings (``READ_*``), destination
seeking's states (``DS_*``) and rewards (``REWARD_*``) by name, and the sizes of the buffers.
"""

from typing import NamedTuple

from nnql_swarm.protocol.jit import Buffer
from nnql_swarm.learning.known_map import WHOLE_MAP
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, VIEW_RADIUS

READ_QL, READ_NNQL, READ_DIR, READ_DAQL = 0, 1, 2, 3
READINGS = {"ql": READ_QL, "nnql": READ_NNQL, "nnql-dir": READ_DIR, "daql": READ_DAQL}
"""The learning algorithms by name, and the neighbour-state reading each uses."""

UNKNOWN_MOVE = N_ACTIONS
"""The move code of a neighbour whose intent is unknown (``READ_DIR``)."""

LP_READING, LP_KNOWN_STATE, LP_RADIUS, LP_SHIELD, LP_RANDOM_STEP = 0, 1, 2, 3, 4
LP_STILL_TERMINAL, LP_MEET_ONLY, LP_DS_STATE, LP_DS_REWARD, LP_DETOUR = 5, 6, 7, 8, 9
LP_STILL_SHIELD, LP_ESCAPE_SHIELD, LP_WALL_SIGHT = 10, 11, 12
LP_FIELDS = 13
FP_ALPHA, FP_GAMMA, FP_BETA, FP_STAY_REWARD = 0, 1, 2, 3
FP_FIELDS = 4

DS_GOAL, DS_WAYPOINT, DS_PROGRESS = 0, 1, 2
DS_STATES = {"goal": DS_GOAL, "waypoint": DS_WAYPOINT, "progress": DS_PROGRESS}
"""Destination seeking's state (``LP_DS_STATE``): the goal's offset (the paper's); the offset of
the next cell of a shortest path on the agent's known map (``learning.known_map``), one of the four
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
and its Q_CA row, which ``learning.readings.read_rows`` writes for the steps that read it."""
assert (NB_X, NB_Y, NB_PARKED) == (1, 2, 8), "learning.known_map.see_parked reads them by number"

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


V_FINAL, V_CROWD = 0, N_ACTIONS
VALUES_SIZE = 2 * N_ACTIONS
"""A learner's ``values`` scratch: the five actions' Q_final (Eq. 7) from ``V_FINAL``, then
their collision-avoidance sums Q_CA(a) (Eq. 6) from ``V_CROWD``."""


class LearnerBuffers(NamedTuple):
    """One learner's buffers, as its kernel reads them: the tables ``q_ds`` and ``q_ca``,
    ``params`` and ``params_f``, its state ``state`` and ``state_f``, its known map ``wmap``
    (``learning.known_map``), its learning record ``rec`` and ``rec_f``, and ``values``, scratch
    for the five actions' values (``VALUES_SIZE``)."""
    q_ds: Buffer
    q_ca: Buffer
    params: Buffer
    params_f: Buffer
    state: Buffer
    state_f: Buffer
    wmap: Buffer
    rec: Buffer
    rec_f: Buffer
    values: Buffer


class Grid(NamedTuple):
    """The grid as a learner meets it: its size and the run's walls, ``first .. last - 1`` of
    ``wall_x``, ``wall_y``, in cell order."""
    width: int
    height: int
    wall_x: Buffer
    wall_y: Buffer
    first: int
    last: int


class Sight(NamedTuple):
    """What a learner observes at a tick: its cell, its goal, its neighbour rows (the first
    ``m`` of ``nb``), and whether this is the episode's first observation (``starts``)."""
    x: int
    y: int
    goal_x: int
    goal_y: int
    nb: Buffer
    m: int
    starts: bool


def learner_params(config) -> tuple[list[int], list[float]]:
    """A learner's ``params`` and ``params_f`` for a run's options (a ``SwarmConfig``; the
    oracle, which learns nothing, reads as QL)."""
    params = [0] * LP_FIELDS
    params[LP_READING] = READINGS.get(config.algo, READ_QL)
    params[LP_KNOWN_STATE] = int(config.known_state)
    params[LP_RADIUS] = config.interaction_radius
    params[LP_SHIELD] = int(config.shield)
    params[LP_RANDOM_STEP] = 0 if config.frozen else config.random_step
    params[LP_STILL_TERMINAL] = int(config.still_terminal)
    params[LP_MEET_ONLY] = int(config.meet_only)
    params[LP_DS_STATE] = DS_STATES[config.ds_state]
    params[LP_DS_REWARD] = DS_REWARDS[config.ds_reward]
    params[LP_DETOUR] = reach(config.interaction_radius) if config.detour else -1
    params[LP_STILL_SHIELD] = int(config.still_shield)
    params[LP_ESCAPE_SHIELD] = int(config.escape_shield)
    params[LP_WALL_SIGHT] = WHOLE_MAP if config.map_known else VIEW_RADIUS
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
