"""One learner at a time: :class:`agent.learning.Learners` for an agent process, bit for bit.

``Learners`` is written over a batch, so that the paper's experiment runs hundreds of learners at
once. An agent process is a batch of one, where a numpy call costs more than its arithmetic, and
every microsecond is on the negotiation's critical path: the agents ranked below wait for this
one's decision. :class:`SingleLearner` holds the same tables as rows of Python floats, the pending
transition (decided, its outcome not yet learned) as a plain :class:`Transition`, and makes the
same decisions and updates in plain Python: the same floating-point operations in the same order
(Eq. 6's sum in einsum's order, :func:`sum_like_einsum`). Its tables are numpy arrays of the
batch's shape on demand (``q_ds``, ``q_ca``), for checkpoints, heat maps and tests;
``tests/test_single.py`` checks that whole swarm runs give identical actions and tables.

Inputs are an agent's own terms: its cell, its goal, the visible neighbours' cells by agent id
(one slot per id, as ``agent.brain`` lays them out) and the announced next cells it knows. What
needs no intent is computed first, as a :class:`Situation`, so that an agent can do it while it
waits for the intents ranked above it, and only the rest once they are in.
"""

import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from agent.learning import DIRECTION_STATES, UNKNOWN_MOVE, Hyper
from protocol.actions import MOVES, N_ACTIONS, N_STATES, VIEW_RADIUS, WINDOW, offset_state_of

Cell = tuple[int, int]


_MOVE_OF_STEP = {(int(dx), int(dy)): a for a, (dx, dy) in enumerate(MOVES)}

def _weight(dx: int, dy: int) -> float:
    """Eq. 6's ``1 / d`` of a neighbour's offset: ``agent.learning.neighbour_weights``'s expression."""
    return 1.0 / max(math.sqrt(dx * dx + dy * dy), 1.0)


_R = VIEW_RADIUS
_WEIGHT_OF_STATE = tuple(_weight(dx, dy) for dx in range(-_R, _R + 1) for dy in range(-_R, _R + 1))
""":func:`_weight` of every offset in view, by its state (``offset_state_of``)."""


def sum_like_einsum(weights: list[tuple[int, float]], rows: list[list[float]],
                    row_of_slot: list[int]) -> list[float]:
    """``sum_m w_m * rows[row_of_slot[m]]`` per action, as ``np.einsum("bm,bma->ba", ...)`` sums
    it: one product, then one addition, slot after slot from 0.0 (``tests/test_single.py`` checks
    that einsum still does). ``weights`` is ``(slot, w)`` in slot order; slots of weight 0 may be
    left out: their products are zeros, which change no sum that starts from 0.0."""
    a0 = a1 = a2 = a3 = a4 = 0.0
    for slot, w in weights:
        r0, r1, r2, r3, r4 = rows[row_of_slot[slot]]
        a0 += w * r0
        a1 += w * r1
        a2 += w * r2
        a3 += w * r3
        a4 += w * r4
    return [a0, a1, a2, a3, a4]


assert N_ACTIONS == 5, "sum_like_einsum is written out for five actions"


class Situation(NamedTuple):
    """One observation in a learner's terms: its cell, the goal's state, the visible neighbours'
    cells by slot, every slot's state read from the current cells, and Eq. 6's weights of the
    visible slots, ``(slot, weight)`` in slot order."""

    own: Cell
    goal_state: int
    cells: dict[int, Cell]
    states: list[int]
    weights: list[tuple[int, float]]


@dataclass(slots=True)
class Transition:
    """The last decision, whose TD update waits for the next observation: the goal's state, the
    action, every slot's state, the visible slots; then the rewards it earned."""

    goal_state: int = 0
    action: int = 0
    nb_states: list[int] = field(default_factory=list)
    visible: list[int] = field(default_factory=list)
    r_ds: float = 0.0
    r_ca: float = 0.0
    terminal: bool = False


class SingleLearner:
    """The state and steps of one ``Learners`` learner (a batch of one), in plain Python."""

    def __init__(self, random_step: int, use_intents: bool, n_neighbours: int,
                 hyper: Hyper = Hyper(), with_direction: bool = False) -> None:
        if random_step < 1:
            raise ValueError("the random step k must be at least 1")
        self.k = int(random_step)
        self.reads_intents = bool(use_intents)
        self.reads_direction = bool(with_direction)
        self.slots = n_neighbours
        self.hyper = hyper
        ca_states = DIRECTION_STATES if with_direction else N_STATES
        self.ds_rows = [[0.0] * N_ACTIONS for _ in range(N_STATES)]
        self.ca_rows = [[0.0] * N_ACTIONS for _ in range(ca_states)]
        self.taken = 0  # actions decided so far (the random step counts them)
        self.last = Transition(nb_states=[0] * n_neighbours)
        self.pending = False  # ``last`` awaits its update

    @property
    def q_ds(self) -> np.ndarray:
        """``Learners.q_ds`` of the batch of one, ``(1, states, actions)``: a copy."""
        return np.array([self.ds_rows])

    @property
    def q_ca(self) -> np.ndarray:
        """``Learners.q_ca`` of the batch of one, ``(1, states, actions)``: a copy."""
        return np.array([self.ca_rows])

    @property
    def actions_taken(self) -> np.ndarray:
        """``Learners.actions_taken`` of the batch of one: a copy."""
        return np.array([self.taken], dtype=np.int64)

    def restore(self, q_ds: np.ndarray, q_ca: np.ndarray, actions_taken: int) -> None:
        """Take the tables and count of a checkpoint (shapes checked by the caller)."""
        self.ds_rows = np.asarray(q_ds, dtype=float).tolist()
        self.ca_rows = np.asarray(q_ca, dtype=float).tolist()
        self.taken = int(actions_taken)

    def record_one(self, r_ds: float, r_ca: float, arrived: bool) -> None:
        """:meth:`Learners.record` for the one learner."""
        last = self.last
        last.r_ds, last.r_ca, last.terminal = float(r_ds), float(r_ca), bool(arrived)

    def forget_pending(self) -> None:
        """:meth:`Learners.forget_pending` for the one learner."""
        self.pending = False

    def pending_as_batch(self) -> dict[str, np.ndarray]:
        """The pending transition as the arrays of ``Learners`` hold it (for comparison)."""
        last = self.last
        visible = np.zeros((1, self.slots), dtype=bool)
        visible[0, last.visible] = True
        return {"_pending": np.array([self.pending]), "_p_goal": np.array([last.goal_state]),
                "_p_action": np.array([last.action]), "_p_nb": np.array([last.nb_states]),
                "_p_visible": visible}

    def situation(self, own: Cell, goal: Cell, cells: dict[int, Cell]) -> "Situation":
        """What a decision reads that no neighbour's intent changes: computed as soon as the
        observation is in, while the agent still waits for the intents ranked above it."""
        ox, oy = own
        absent = self._state_of_cell((0, 0), ox, oy)
        states = [absent] * self.slots
        weights = []
        unknown_move = N_STATES * UNKNOWN_MOVE if self.reads_direction else 0
        for slot in sorted(cells):
            dx, dy = cells[slot][0] - ox, cells[slot][1] - oy
            if -_R <= dx <= _R and -_R <= dy <= _R:  # always, for a visible neighbour
                state = (dx + _R) * WINDOW + dy + _R  # offset_state_of, no clipping needed
                weights.append((slot, _WEIGHT_OF_STATE[state]))
            else:
                state = offset_state_of(dx, dy)
                weights.append((slot, _weight(dx, dy)))
            states[slot] = state + unknown_move
        return Situation(own, offset_state_of(goal[0] - ox, goal[1] - oy), cells, states, weights)

    def decide_one(self, situation: "Situation", next_cells: dict[int, Cell],
                   random_action: int, ties: list[float]) -> int:
        """:meth:`Learners.decide` for the one (active) learner; returns its action.
        ``next_cells``: the announced next cells of the neighbours whose intents are known."""
        nb_states = self._nb_states(situation, next_cells)
        if self.pending:
            self._complete_one(situation.goal_state, nb_states)
        values = self._q_final_one(situation, nb_states)
        best, greedy, top = max(values), 0, -1.0
        for a, value in enumerate(values):  # argmax_ties: the best's largest tie-breaker, first
            if value >= best and ties[a] > top:
                greedy, top = a, ties[a]
        self.taken += 1
        action = int(random_action) if self.taken % self.k == 0 else greedy
        self.last = Transition(situation.goal_state, action, nb_states,
                               [slot for slot, _ in situation.weights])
        self.pending = True
        return action

    def finish_one(self, situation: "Situation") -> None:
        """:meth:`Learners.finish` for the one learner (the QL reading of ``s'``)."""
        if self.pending:
            self._complete_one(situation.goal_state, self._nb_states(situation, {}))

    def _state_of_cell(self, cell: Cell, ox: int, oy: int) -> int:
        """A neighbour slot's state from the cell it is in (no intent known)."""
        state = offset_state_of(cell[0] - ox, cell[1] - oy)
        return state + N_STATES * UNKNOWN_MOVE if self.reads_direction else state

    def _nb_states(self, situation: "Situation", next_cells: dict[int, Cell]) -> list[int]:
        """``neighbour_states`` for every slot: the situation's, with each known intent's
        announced cell in place of the current one (a slot out of view reads cell (0, 0))."""
        if not self.reads_intents or not next_cells:
            return situation.states
        ox, oy = situation.own
        states = list(situation.states)
        for slot, (x, y) in next_cells.items():
            state = offset_state_of(x - ox, y - oy)
            if self.reads_direction:
                cx, cy = situation.cells[slot]
                state += N_STATES * _MOVE_OF_STEP[(x - cx, y - cy)]
            states[slot] = state
        return states

    def _q_final_one(self, situation: "Situation", nb_states: list[int]) -> list[float]:
        """Eq. 6 and 7 as ``Learners._q_final`` computes them (the same products and sums)."""
        ca = sum_like_einsum(situation.weights, self.ca_rows, nb_states)
        beta, rest = self.hyper.beta, 1.0 - self.hyper.beta
        return [beta * ds + rest * c for ds, c in zip(self.ds_rows[situation.goal_state], ca)]

    def _complete_one(self, next_goal: int, next_nb: list[int]) -> None:
        """``Learners._complete`` for the one learner: Eq. 9, then Eq. 10 slot by slot, each as
        ``agent.learning.td_update`` computes it (the same operations in the same order)."""
        last, alpha, gamma = self.last, self.hyper.alpha, self.hyper.gamma
        action = last.action
        row = self.ds_rows[last.goal_state]
        current = row[action]
        target = last.r_ds + gamma * (0.0 if last.terminal else 1.0) * max(self.ds_rows[next_goal])
        row[action] = current + alpha * (target - current)
        ca_rows, states, reward = self.ca_rows, last.nb_states, last.r_ca
        for slot in last.visible:
            row = ca_rows[states[slot]]
            current = row[action]
            target = reward + gamma * max(ca_rows[next_nb[slot]])  # bootstrap 1: gamma * 1.0 == gamma
            row[action] = current + alpha * (target - current)
        self.pending = False
