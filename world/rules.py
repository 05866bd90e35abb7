"""Pure grid-world rules: simultaneous moves, collisions and rewards, over a batch of worlds.

Every function takes arrays with a leading batch axis ``B`` (independent worlds) and an agent
axis ``N``, so one code path serves the single world of a swarm run (``B = 1``) and the hundreds
of independent runs of the paper's experiment.

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

import numpy as np

from protocol.actions import intended_cell

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


def collision_reward(collided: np.ndarray) -> np.ndarray:
    """The paper's collision-avoidance reward: 10 without a collision, 0 with one."""
    return np.where(collided, 0.0, CA_REWARD)


def shortest_steps(start: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """The fewest moves from start to goal on an empty grid (Manhattan distance)."""
    return np.sum(np.abs(np.asarray(goal) - np.asarray(start)), axis=-1)


def invariant_violations(
    before: np.ndarray, after: np.ndarray, count_swaps: bool
) -> list[str]:
    """What a tick broke, for one world (``(N, 2)`` cells): shared cells, swap-throughs.

    Plain Python over the cells: the world checks every tick, between an agent's last intent
    and the next observations, where numpy's per-call cost on a handful of cells shows."""
    problems = []
    was = [tuple(cell) for cell in before.tolist()]
    now = [tuple(cell) for cell in after.tolist()]
    if len(set(now)) != len(now):
        problems.append("two agents share a cell")
    if count_swaps:
        who_was_at = {cell: j for j, cell in enumerate(was)}
        for i, (old, new) in enumerate(zip(was, now)):
            j = who_was_at.get(new) if new != old else None
            if j is not None and now[j] == old:
                problems.append(f"agent {i} swapped through another agent")
    return problems
