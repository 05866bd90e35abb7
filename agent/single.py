"""One learner at a time: :class:`agent.learning.Learners` for an agent process, bit for bit.

``Learners`` is written over a batch, so that the paper's experiment runs hundreds of learners at
once. An agent process is a batch of one, where each of the sixty-odd small numpy calls of a
decision costs more than its arithmetic, and every microsecond is on the negotiation's critical
path: the agents ranked below wait for this one's decision. :class:`SingleLearner` keeps the
tables and counters of ``Learners`` (so checkpoints and heat maps are unchanged), holds the
pending transition (decided, its outcome not yet learned) as a plain :class:`Transition`, and makes
the same decisions and updates in plain Python: the same floating-point operations in the same
order, and the one sum whose order numpy chooses (Eq. 6) through the very same ``einsum`` call.
``tests/test_single.py`` checks that whole swarm runs give identical actions and tables.

Inputs are an agent's own terms: its cell, its goal, the visible neighbours' cells by agent id
(one slot per id, as ``agent.brain`` lays them out) and the announced next cells it knows. What
needs no intent is computed first, as a :class:`Situation`, so that an agent can do it while it
waits for the intents ranked above it, and only the rest once they are in.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from agent.learning import UNKNOWN_MOVE, Hyper, Learners
from protocol.actions import MOVES, N_STATES, offset_state_of

Cell = tuple[int, int]


_MOVE_OF_STEP = {(int(dx), int(dy)): a for a, (dx, dy) in enumerate(MOVES)}


@dataclass(frozen=True, slots=True)
class Situation:
    """One observation in a learner's terms: its cell, the goal's state, the visible neighbours'
    cells by slot, every slot's state read from the current cells, and Eq. 6's weights."""

    own: Cell
    goal_state: int
    cells: dict[int, Cell]
    states: list[int]
    weights: np.ndarray  # (1, slots)


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


class SingleLearner(Learners):
    """A batch of one ``Learners`` whose steps take scalars instead of a :class:`View`."""

    def __init__(self, random_step: int, use_intents: bool, n_neighbours: int,
                 hyper: Hyper = Hyper(), with_direction: bool = False) -> None:
        super().__init__(np.array([random_step]), np.array([use_intents]), n_neighbours, hyper,
                         np.array([with_direction]))
        self.k = int(random_step)
        self.reads_intents = bool(use_intents)
        self.reads_direction = bool(with_direction)
        self.slots = n_neighbours
        self.last = Transition(nb_states=[0] * n_neighbours)
        self.pending = False  # ``last`` awaits its update

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
        state_of_cell = self._state_of_cell
        states = [state_of_cell(cells.get(slot, (0, 0)), ox, oy) for slot in range(self.slots)]
        weights = [0.0] * self.slots
        for slot, (x, y) in cells.items():
            dx, dy = x - ox, y - oy
            weights[slot] = 1.0 / max(math.sqrt(dx * dx + dy * dy), 1.0)
        return Situation(own, offset_state_of(goal[0] - ox, goal[1] - oy), cells, states,
                         np.array([weights]))

    def decide_one(self, situation: "Situation", next_cells: dict[int, Cell],
                   random_action: int, ties: list[float]) -> int:
        """:meth:`Learners.decide` for the one (active) learner; returns its action.
        ``next_cells``: the announced next cells of the neighbours whose intents are known."""
        nb_states = self._nb_states(situation, next_cells)
        if self.pending:
            self._complete_one(situation.goal_state, nb_states)
        values = self._q_final_one(situation, nb_states)
        best = max(values)
        greedy = max((a for a in range(len(values)) if values[a] >= best),
                     key=lambda a: (ties[a], -a))
        taken = int(self.actions_taken[0])
        action = int(random_action) if (taken + 1) % self.k == 0 else greedy
        self.actions_taken[0] = taken + 1
        self.last = Transition(situation.goal_state, action, nb_states, sorted(situation.cells))
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
        q_ca = np.einsum("bm,bma->ba", situation.weights, self.q_ca[0][nb_states][None])
        beta, rest = self.hyper.beta, 1.0 - self.hyper.beta
        return [beta * ds + rest * ca
                for ds, ca in zip(self.q_ds[0, situation.goal_state].tolist(), q_ca[0].tolist())]

    def _complete_one(self, next_goal: int, next_nb: list[int]) -> None:
        """``Learners._complete`` for the one learner: Eq. 9, then Eq. 10 slot by slot."""
        last, td = self.last, self._td
        td(self.q_ds[0], last.goal_state, last.action, last.r_ds, next_goal,
           0.0 if last.terminal else 1.0)
        q_ca, states = self.q_ca[0], last.nb_states
        for slot in last.visible:
            td(q_ca, states[slot], last.action, last.r_ca, next_nb[slot], 1.0)
        self.pending = False

    def _td(self, table: np.ndarray, state: int, action: int, reward: float, next_state: int,
            bootstrap: float) -> None:
        """``agent.learning.td_update`` for one entry, in the same order of operations."""
        h = self.hyper
        current = table.item(state, action)
        target = reward + h.gamma * bootstrap * max(table[next_state].tolist())
        table[state, action] = current + h.alpha * (target - current)
