"""The action set, its move table and the egocentric state window, shared by agents and world.

Positions are integer cells ``(x, y)`` on a ``width x height`` grid, ``x`` growing to the right and
``y`` growing downwards (row-major, as images and the Rerun viewer draw them), so UP is ``y - 1``.
"""

import numpy as np

UP, DOWN, LEFT, RIGHT, STAY = 0, 1, 2, 3, 4
"""Action indices, in the paper's order (UP, DOWN, LEFT, RIGHT, DON'T MOVE)."""

ACTION_NAMES = ("UP", "DOWN", "LEFT", "RIGHT", "STAY")
N_ACTIONS = len(ACTION_NAMES)

MOVES = np.array([(0, -1), (0, 1), (-1, 0), (1, 0), (0, 0)], dtype=np.int64)
"""MOVES[a] is the (dx, dy) displacement of action a."""

VIEW_RADIUS = 10
"""An agent sees cells at most this many cells away along each axis (Chebyshev distance)."""

WINDOW = 2 * VIEW_RADIUS + 1
N_STATES = WINDOW * WINDOW
"""441 egocentric states: one per relative offset (dx, dy) in [-10, 10]^2."""


def offset_state(offset: np.ndarray) -> np.ndarray:
    """Map relative offsets ``(..., 2)`` to egocentric state indices ``(...)``.

    Offsets beyond the window are clipped to its edge, which keeps their direction.
    """
    clipped = np.minimum(np.maximum(offset, -VIEW_RADIUS), VIEW_RADIUS) + VIEW_RADIUS
    return clipped[..., 0] * WINDOW + clipped[..., 1]


def offset_state_of(dx: int, dy: int) -> int:
    """:func:`offset_state` for one offset, in plain Python (an agent's decision path)."""
    dx = min(max(dx, -VIEW_RADIUS), VIEW_RADIUS) + VIEW_RADIUS
    dy = min(max(dy, -VIEW_RADIUS), VIEW_RADIUS) + VIEW_RADIUS
    return dx * WINDOW + dy


def state_offset(state: np.ndarray) -> np.ndarray:
    """Inverse of :func:`offset_state` on the window: state indices to offsets ``(..., 2)``."""
    state = np.asarray(state)
    return np.stack([state // WINDOW - VIEW_RADIUS, state % WINDOW - VIEW_RADIUS], axis=-1)


def in_view(offset: np.ndarray) -> np.ndarray:
    """True where a relative offset ``(..., 2)`` lies inside the egocentric window."""
    return np.all(np.abs(offset) <= VIEW_RADIUS, axis=-1)


def sees(a: tuple[int, int], b: tuple[int, int]) -> bool:
    """Whether an agent at cell ``a`` sees cell ``b``: :func:`in_view` for one pair, in plain
    Python (it runs on the negotiation's critical path, where numpy's call overhead shows)."""
    return abs(b[0] - a[0]) <= VIEW_RADIUS and abs(b[1] - a[1]) <= VIEW_RADIUS


def intended_cell(position: np.ndarray, action: np.ndarray, width: int, height: int) -> np.ndarray:
    """The cell an action aims at; a move off the grid aims at the current cell."""
    target = position + MOVES[action]
    on_grid = (
        (target[..., 0] >= 0)
        & (target[..., 0] < width)
        & (target[..., 1] >= 0)
        & (target[..., 1] < height)
    )
    return np.where(on_grid[..., None], target, position)


_STEPS = tuple((int(dx), int(dy)) for dx, dy in MOVES)


def intended_cell_of(x: int, y: int, action: int, width: int, height: int) -> tuple[int, int]:
    """:func:`intended_cell` for one cell, in plain Python (on the negotiation's critical path)."""
    dx, dy = _STEPS[action]
    tx, ty = x + dx, y + dy
    return (tx, ty) if 0 <= tx < width and 0 <= ty < height else (x, y)
