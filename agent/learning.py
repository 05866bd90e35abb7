"""The learning core of QL and nnQL, pure numpy, over a batch of independent learners.

One learner holds two tables over the 441 egocentric states (``protocol.actions``):
``Q_DS[s_goal, a]`` seeks the destination, ``Q_CA[s_i, a]`` avoids neighbours (one table shared by
all neighbours). A batch of ``B`` learners, each with ``M`` neighbour slots, is driven step by step:

1. :meth:`Learners.decide` completes each active learner's pending update (Eq. 9, 10) with the new
   view as ``s'``, then picks the action (Eq. 6, 7, 8): ``Q_final = beta Q_DS + (1 - beta) Q_CA``,
   ``Q_CA(a) = sum_i (1/d_i) Q_CA[s_i, a]`` over visible neighbours, argmax with ties broken by the
   learner's own noise; every ``k``-th action (the paper's "random step") is random instead.
2. :meth:`Learners.record` stores the rewards of that action.
3. :meth:`Learners.finish` completes the pending update of learners leaving the episode.

The neighbour state is where QL and nnQL differ (Eq. 6, DESIGN §2): QL reads
``s_i = neighbour's current cell - own cell``; nnQL (n = 1) reads
``s_i = neighbour's announced next cell - own cell`` wherever that announcement is known, and falls
back to the QL state where it is not. ``s`` and ``s'`` are read the same way, so an nnQL update waits
for the neighbours' next announcements: that is why updates complete at the next decision.
At an episode's end nobody announces again, so ``s'`` falls back to the QL state there.

A batch of one is an agent process; a batch of hundreds is the paper's experiment, each run exactly
as it would be alone (every learner draws only from its own noise).
"""

from dataclasses import dataclass

import numpy as np

from protocol.actions import MOVES, N_ACTIONS, N_STATES, STAY, offset_state

DEFAULT_ALPHA = 0.9
DEFAULT_GAMMA = 0.6
DEFAULT_BETA = 0.5
"""beta is not given in the paper; README §Readings has the sweep behind this default."""


@dataclass(frozen=True)
class Hyper:
    """Learning rate, discount and the DS / CA mixing weight of Eq. 7."""

    alpha: float = DEFAULT_ALPHA
    gamma: float = DEFAULT_GAMMA
    beta: float = DEFAULT_BETA


@dataclass
class View:
    """What each learner of a batch sees at one decision.

    ``nb_*`` arrays have one slot per potential neighbour (``M`` slots). ``nb_next`` is read only
    where ``nb_known`` is set; ``nb_visible`` says which slots are in view (and so count).
    """

    own: np.ndarray  # (B, 2) own cell
    goal: np.ndarray  # (B, 2) goal cell
    nb_cells: np.ndarray  # (B, M, 2) neighbours' current cells
    nb_next: np.ndarray  # (B, M, 2) neighbours' announced next cells
    nb_known: np.ndarray  # (B, M) bool: the announcement is known
    nb_visible: np.ndarray  # (B, M) bool: the neighbour is in view

    def without_intents(self) -> "View":
        """The same view with no announcement known (the QL reading)."""
        return View(
            self.own, self.goal, self.nb_cells, self.nb_next,
            np.zeros_like(self.nb_known), self.nb_visible,
        )


@dataclass(frozen=True)
class EpisodeNoise:
    """A learner's random draws for one episode: the exploring actions and the tie-breakers."""

    random_actions: np.ndarray  # (max_steps,)
    tie_breakers: np.ndarray  # (max_steps, N_ACTIONS) in [0, 1)

    @staticmethod
    def draw(rng: np.random.Generator, max_steps: int) -> "EpisodeNoise":
        """Draw one episode's noise; the order of draws is part of the determinism contract."""
        return EpisodeNoise(
            random_actions=rng.integers(0, N_ACTIONS, size=max_steps, dtype=np.int64),
            tie_breakers=rng.random((max_steps, N_ACTIONS)),
        )


def goal_state(view: View) -> np.ndarray:
    """The destination-seeking state: the goal's offset from the learner."""
    return offset_state(view.goal - view.own)


UNKNOWN_MOVE = N_ACTIONS
"""The move code of a neighbour whose announcement is unknown (direction-aware reading)."""

DIRECTION_STATES = N_STATES * (N_ACTIONS + 1)
"""Collision-avoidance states of the direction-aware reading: offset x (5 moves + unknown)."""

_MOVE_CODE = np.full((3, 3), STAY, dtype=np.int64)
for _action, (_dx, _dy) in enumerate(MOVES):
    _MOVE_CODE[_dx + 1, _dy + 1] = _action


def neighbour_states(
    view: View, use_intents: np.ndarray, with_direction: np.ndarray | None = None
) -> np.ndarray:
    """The collision-avoidance state of each neighbour slot ``(B, M)``.

    QL reads the neighbour's current cell, nnQL its announced next cell (where known). The
    direction-aware reading (``with_direction``, beyond the paper) adds the announced move, so
    that a neighbour about to step into this agent's cell from the left differs from one coming
    from the right: it can see a swap coming, which the announced cell alone cannot.
    """
    read_next = use_intents[:, None] & view.nb_known
    cells = np.where(read_next[..., None], view.nb_next, view.nb_cells)
    states = offset_state(cells - view.own[:, None, :])
    if with_direction is None or not with_direction.any():
        return states
    step = np.where(read_next[..., None], view.nb_next - view.nb_cells, 0)
    moves = np.where(read_next, _MOVE_CODE[step[..., 0] + 1, step[..., 1] + 1], UNKNOWN_MOVE)
    return np.where(with_direction[:, None], states + N_STATES * moves, states)


def neighbour_weights(view: View) -> np.ndarray:
    """``1 / d_i`` for visible neighbours (Euclidean distance now), 0 for the others."""
    distance = np.sqrt(np.sum((view.nb_cells - view.own[:, None, :]) ** 2, axis=-1))
    return np.where(view.nb_visible, 1.0 / np.maximum(distance, 1.0), 0.0)


def argmax_ties(values: np.ndarray, tie_breakers: np.ndarray) -> np.ndarray:
    """Row-wise argmax of ``(B, A)``; among exact ties, the one with the largest tie-breaker."""
    best = values >= values.max(axis=1, keepdims=True)
    return np.argmax(np.where(best, tie_breakers, -1.0), axis=1)


def td_update(
    table: np.ndarray,
    rows: np.ndarray,
    states: np.ndarray,
    actions: np.ndarray,
    rewards: np.ndarray,
    next_states: np.ndarray,
    bootstrap: np.ndarray,
    hyper: Hyper,
) -> None:
    """Eq. 9 / 10 in place for the learners ``rows``: ``Q += alpha (r + gamma max Q' - Q)``.

    ``bootstrap`` is 0 where the episode ended in a terminal state (the goal), else 1.
    """
    current = table[rows, states, actions]
    future = table[rows, next_states].max(axis=1)
    target = rewards + hyper.gamma * bootstrap * future
    table[rows, states, actions] = current + hyper.alpha * (target - current)


class Learners:
    """A batch of independent QL / nnQL learners and their pending transitions."""

    def __init__(
        self,
        random_step: np.ndarray,
        use_intents: np.ndarray,
        n_neighbours: int,
        hyper: Hyper = Hyper(),
        with_direction: np.ndarray | None = None,
    ) -> None:
        self.random_step = np.asarray(random_step, dtype=np.int64)
        self.use_intents = np.asarray(use_intents, dtype=bool)
        self.with_direction = (np.zeros_like(self.use_intents) if with_direction is None
                               else np.asarray(with_direction, dtype=bool))
        if self.random_step.shape != self.use_intents.shape or self.random_step.ndim != 1:
            raise ValueError("random_step and use_intents must be 1-D arrays of the same length")
        if np.any(self.random_step < 1):
            raise ValueError("the random step k must be at least 1")
        batch = self.random_step.shape[0]
        self.hyper = hyper
        self.q_ds = np.zeros((batch, N_STATES, N_ACTIONS))
        ca_states = DIRECTION_STATES if self.with_direction.any() else N_STATES
        self.q_ca = np.zeros((batch, ca_states, N_ACTIONS))
        self.actions_taken = np.zeros(batch, dtype=np.int64)
        self._pending = np.zeros(batch, dtype=bool)
        self._p_goal = np.zeros(batch, dtype=np.int64)
        self._p_action = np.zeros(batch, dtype=np.int64)
        self._p_nb = np.zeros((batch, n_neighbours), dtype=np.int64)
        self._p_visible = np.zeros((batch, n_neighbours), dtype=bool)
        self._p_r_ds = np.zeros(batch)
        self._p_r_ca = np.zeros(batch)
        self._p_terminal = np.zeros(batch, dtype=bool)

    @property
    def batch(self) -> int:
        return self.random_step.shape[0]

    def q_final(self, view: View) -> np.ndarray:
        """Eq. 6 and 7 for every learner: ``(B, A)``."""
        return self._q_final(view, goal_state(view), neighbour_states(view, self.use_intents, self.with_direction))

    def _q_final(self, view: View, goal_states: np.ndarray, nb_states: np.ndarray) -> np.ndarray:
        rows = np.arange(self.batch)
        q_ds = self.q_ds[rows, goal_states]
        q_ca = np.einsum("bm,bma->ba", neighbour_weights(view), self.q_ca[rows[:, None], nb_states])
        return self.hyper.beta * q_ds + (1.0 - self.hyper.beta) * q_ca

    def decide(
        self,
        view: View,
        active: np.ndarray,
        random_actions: np.ndarray,
        tie_breakers: np.ndarray,
    ) -> np.ndarray:
        """Complete the active learners' pending updates with this view, then choose (Eq. 8).

        Returns actions ``(B,)``; entries of inactive learners are meaningless.
        """
        active = np.asarray(active, dtype=bool)
        goal_states = goal_state(view)
        nb_states = neighbour_states(view, self.use_intents, self.with_direction)
        self._complete(active & self._pending, goal_states, nb_states)
        greedy = argmax_ties(self._q_final(view, goal_states, nb_states), tie_breakers)
        explore = (self.actions_taken + 1) % self.random_step == 0
        actions = np.where(explore, random_actions, greedy)
        self.actions_taken += active
        # An inactive learner keeps whatever transition it still has pending.
        self._pending = active | self._pending
        self._p_goal = np.where(active, goal_states, self._p_goal)
        self._p_action = np.where(active, actions, self._p_action)
        self._p_nb = np.where(active[:, None], nb_states, self._p_nb)
        self._p_visible = np.where(active[:, None], view.nb_visible, self._p_visible)
        return actions

    def record(self, r_ds: np.ndarray, r_ca: np.ndarray, arrived: np.ndarray) -> None:
        """Store the rewards of the last decided actions; ``arrived`` marks terminal steps."""
        self._p_r_ds = np.asarray(r_ds, dtype=float)
        self._p_r_ca = np.asarray(r_ca, dtype=float)
        self._p_terminal = np.asarray(arrived, dtype=bool)

    def finish(self, mask: np.ndarray, view: View) -> None:
        """Complete the pending updates of learners leaving the episode (QL reading of ``s'``)."""
        ql_view = view.without_intents()
        self._complete(
            np.asarray(mask, dtype=bool) & self._pending,
            goal_state(ql_view), neighbour_states(ql_view, self.use_intents, self.with_direction),
        )

    def forget_pending(self) -> None:
        """Drop every pending transition (its episode was abandoned, e.g. the world restarted)."""
        self._pending[:] = False

    def _complete(self, mask: np.ndarray, goal_states: np.ndarray, nb_states: np.ndarray) -> None:
        """Eq. 9 and 10 for the pending transitions of ``mask``, with ``s'`` read from the states."""
        if not mask.any():
            return
        rows = np.flatnonzero(mask)
        action = self._p_action[rows]
        next_goal = goal_states[rows]
        bootstrap = (~self._p_terminal[rows]).astype(float)
        td_update(
            self.q_ds, rows, self._p_goal[rows], action, self._p_r_ds[rows],
            next_goal, bootstrap, self.hyper,
        )
        self._update_ca(rows, action, self._p_nb[rows], nb_states[rows], self._p_visible[rows])
        self._pending[rows] = False

    def _update_ca(
        self,
        rows: np.ndarray,
        action: np.ndarray,
        states: np.ndarray,
        next_states: np.ndarray,
        visible: np.ndarray,
    ) -> None:
        """Eq. 10 once per visible neighbour, in slot order, for every learner of ``rows``.

        The paper repeats the update neighbour by neighbour; where no update of a learner can see
        another's effect (no repeated state, no ``s'`` equal to an earlier ``s``) all of them are
        applied at once, and only the rare learners with such overlaps go slot by slot.
        """
        slots = states.shape[1]
        earlier = np.tril(np.ones((slots, slots), dtype=bool), k=-1)[None]
        both_seen = visible[:, :, None] & visible[:, None, :] & earlier
        overlap = both_seen & (
            (states[:, :, None] == states[:, None, :])
            | (next_states[:, :, None] == states[:, None, :])
        )
        sequential = overlap.any(axis=(1, 2))
        ones = np.ones(rows.size)
        rewards = self._p_r_ca[rows]
        fast = ~sequential[:, None] & visible
        if fast.any():
            at, slot = np.nonzero(fast)
            td_update(self.q_ca, rows[at], states[at, slot], action[at], rewards[at],
                      next_states[at, slot], ones[at], self.hyper)
        slow = sequential[:, None] & visible
        for slot in np.flatnonzero(slow.any(axis=0)):
            at = np.flatnonzero(slow[:, slot])
            td_update(self.q_ca, rows[at], states[at, slot], action[at], rewards[at],
                      next_states[at, slot], ones[at], self.hyper)
