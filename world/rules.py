"""Pure grid-world rules: simultaneous moves, collisions and rewards, over a batch of worlds or one.

The batch functions (:func:`arbitrate`, :func:`destination_reward`, :func:`collision_reward`) take
arrays with a leading batch axis ``B`` (independent worlds) and an agent axis ``N``: the paper's
experiment runs hundreds of worlds at once through them. The single world of a swarm run is a
batch of one, where numpy's per-call cost on a handful of cells outweighs the arithmetic, and
the world's tick is on the swarm's critical path (between the last agent's intent and the next
observations). So each batch function has a one-world twin in plain Python next to it
(:func:`arbitrate_one`, :func:`destination_reward_of`, :func:`collision_reward_of`) over cells as
``(x, y)`` tuples, giving bit for bit the same results (``tests/test_one_world.py``);
:func:`invariant_violations` only ever serves one world and is plain Python alone.

Collision rules (DESIGN §3):

- All intents of a tick are applied at once. A move off the grid aims at the current cell: the
  agent stays, and that is no collision.
- A collision is two agents trying to occupy the same cell in the same step: two moving into one
  cell, or one moving into a cell whose occupant stays or is blocked. Blocking propagates along
  chains until nothing changes (a fixed point): A -> B's cell, B -> C's cell, C stays blocks B,
  which then blocks A.
- Rotations (cycles of four or more agents; a grid has no cycle of three) all move. Two agents swapping cells pass through each other
  unless ``count_swaps`` is set; then both are blocked and both collide.
- Colliding agents stay where they were. Every agent in a conflicting pair is marked collided,
  the one that stays included (it was hit); each counts one collision per step, however many
  agents it met.
"""

import math
from collections.abc import Sequence

import numpy as np

from protocol.actions import intended_cell, intended_cell_of

Cell = tuple[int, int]

GOAL_REWARD = 10.0
"""The destination-seeking reward on arriving (the paper leaves it open, README §Readings)."""

CA_REWARD = 10.0
"""The collision-avoidance reward for a step without collision (0 with one), as in the paper."""


def arbitrate(
    positions: np.ndarray,
    actions: np.ndarray,
    width: int,
    height: int,
    count_swaps: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """Apply one tick of simultaneous moves.

    ``positions`` is ``(B, N, 2)`` with pairwise distinct cells per world, ``actions`` is
    ``(B, N)``. Returns the new positions ``(B, N, 2)`` and ``collided`` ``(B, N)``.
    """
    positions = np.asarray(positions, dtype=np.int64)
    target = intended_cell(positions, np.asarray(actions), width, height)
    moving = np.any(target != positions, axis=-1)
    n = positions.shape[1]
    others = ~np.eye(n, dtype=bool)[None]
    blocked = np.zeros(moving.shape, dtype=bool)
    collided = np.zeros(moving.shape, dtype=bool)
    if count_swaps:
        aims_at = np.all(target[:, :, None, :] == positions[:, None, :, :], axis=-1)
        swap_pair = aims_at & np.swapaxes(aims_at, 1, 2) & others
    while True:
        going = moving & ~blocked
        final = np.where(going[..., None], target, positions)
        conflict = np.all(final[:, :, None, :] == final[:, None, :, :], axis=-1) & others
        if count_swaps:
            conflict |= swap_pair & going[:, :, None] & going[:, None, :]
        in_conflict = np.any(conflict, axis=2)
        collided |= in_conflict
        newly_blocked = in_conflict & going
        if not newly_blocked.any():
            return final, collided
        blocked |= newly_blocked


def arbitrate_one(
    cells: Sequence[Cell],
    actions: Sequence[int],
    width: int,
    height: int,
    count_swaps: bool,
) -> tuple[list[Cell], list[bool]]:
    """:func:`arbitrate` for one world, in plain Python: new cells and ``collided``, by agent.

    ``cells`` are pairwise distinct. The batch's rounds: each round finds the agents sharing a
    cell, marks them collided and blocks at once those of them still moving, until a round
    blocks nobody. A swapping pair (when swaps count) is blocked before the first round rather
    than in it: whoever aims at one of its cells meets one of the two either way, so the
    collided agents and the fixed point are the same.
    """
    final = [intended_cell_of(x, y, a, width, height) for (x, y), a in zip(cells, actions)]
    collided = [False] * len(cells)
    blocked = _swapping(cells, final) if count_swaps else []
    while True:
        for i in blocked:
            final[i] = cells[i]
            collided[i] = True
        sharing = _sharing_a_cell(final)
        for i in sharing:
            collided[i] = True
        blocked = [i for i in sharing if final[i] != cells[i]]
        if not blocked:
            return final, collided


def _swapping(cells: Sequence[Cell], targets: Sequence[Cell]) -> list[int]:
    """The agents whose target is the cell of an agent whose target is theirs."""
    who_is_at = {cell: j for j, cell in enumerate(cells)}
    swapping = []
    for i, target in enumerate(targets):
        j = who_is_at.get(target)
        if j is not None and j != i and targets[j] == cells[i]:
            swapping.append(i)
    return swapping


def _sharing_a_cell(final: list[Cell]) -> set[int]:
    """The agents whose cell is another agent's too."""
    first_at: dict[Cell, int] = {}
    sharing = set()
    for i, cell in enumerate(final):
        j = first_at.setdefault(cell, i)
        if j != i:
            sharing.update((i, j))
    return sharing


def destination_reward(
    before: np.ndarray, after: np.ndarray, goal: np.ndarray, goal_reward: float = GOAL_REWARD
) -> np.ndarray:
    """The paper's destination-seeking reward for cells ``(..., 2)``.

    ``1/d`` if the Euclidean distance ``d`` to the goal decreased, ``0.5/d`` if it stayed the
    same, 0 if it grew, and ``goal_reward`` on arriving. Distances are compared as exact integer
    squares, so "stayed the same" never depends on rounding.
    """
    d2_before = np.sum((goal - before) ** 2, axis=-1)
    d2_after = np.sum((goal - after) ** 2, axis=-1)
    d_after = np.sqrt(np.maximum(d2_after, 1))
    reward = np.where(
        d2_after < d2_before, 1.0 / d_after, np.where(d2_after == d2_before, 0.5 / d_after, 0.0)
    )
    return np.where(d2_after == 0, goal_reward, reward)


def destination_reward_of(
    before: Cell, after: Cell, goal: Cell, goal_reward: float = GOAL_REWARD
) -> float:
    """:func:`destination_reward` for one agent's cells, in plain Python, bit for bit: the same
    exact integer squares, and ``math.sqrt`` and ``/`` round correctly, as numpy's do."""
    d2_before = (goal[0] - before[0]) ** 2 + (goal[1] - before[1]) ** 2
    d2_after = (goal[0] - after[0]) ** 2 + (goal[1] - after[1]) ** 2
    if d2_after == 0:
        return float(goal_reward)
    if d2_after > d2_before:
        return 0.0
    return (1.0 if d2_after < d2_before else 0.5) / math.sqrt(d2_after)


def collision_reward(collided: np.ndarray) -> np.ndarray:
    """The paper's collision-avoidance reward: 10 without a collision, 0 with one."""
    return np.where(collided, 0.0, CA_REWARD)


def collision_reward_of(collided: bool) -> float:
    """:func:`collision_reward` for one agent."""
    return 0.0 if collided else CA_REWARD


def shortest_steps(start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The fewest moves from start to goal on an empty grid (Manhattan distance)."""
    return np.sum(np.abs(np.asarray(goal) - np.asarray(start)), axis=-1)


def invariant_violations(
    before: Sequence[Cell] | np.ndarray, after: Sequence[Cell] | np.ndarray, count_swaps: bool
) -> list[str]:
    """What a tick broke, for one world's cells (``(x, y)`` pairs): shared cells, swap-throughs.

    Plain Python over the cells: the world checks every tick, between an agent's last intent
    and the next observations, where numpy's per-call cost on a handful of cells shows."""
    problems = []
    was = list(map(tuple, before))
    now = list(map(tuple, after))
    if len(set(now)) != len(now):
        problems.append("two agents share a cell")
    if count_swaps:
        problems.extend(f"agent {i} swapped through another agent" for i in _swapping(was, now))
    return problems
