"""The action set, its move table and the egocentric state window, shared by agents and world.

Positions are integer cells ``(x, y)`` on a ``width x height`` grid, ``x`` growing to the right and
``y`` growing downwards (row-major, as images and the Rerun viewer draw them), so UP is ``y - 1``.
The scalar functions are kernel functions (``protocol.jit``): the learner, the world and the
simulator all call these very ones.
"""

import numpy as np

from nnql_swarm.protocol.jit import kernel

UP, DOWN, LEFT, RIGHT, STAY = 0, 1, 2, 3, 4
"""Action indices, in the paper's order (UP, DOWN, LEFT, RIGHT, DON'T MOVE)."""

ACTION_NAMES = ("UP", "DOWN", "LEFT", "RIGHT", "STAY")
N_ACTIONS = len(ACTION_NAMES)

STEP_X = (0, 0, -1, 1, 0)
STEP_Y = (-1, 1, 0, 0, 0)
"""The (dx, dy) displacement of action a is (STEP_X[a], STEP_Y[a])."""

MOVES = np.array(list(zip(STEP_X, STEP_Y)), dtype=np.int64)
"""The same displacements as an ``(N_ACTIONS, 2)`` array, for drawing."""

VIEW_RADIUS = 10
"""An agent sees cells at most this many cells away along each axis (Chebyshev distance)."""

WINDOW = 2 * VIEW_RADIUS + 1
N_STATES = WINDOW * WINDOW
"""441 egocentric states: one per relative offset (dx, dy) in [-10, 10]^2."""


@kernel
def offset_state(dx, dy):
    """The egocentric state of a relative offset; offsets beyond the window are clipped to its
    edge, which keeps their direction."""
    if dx < -VIEW_RADIUS:
        dx = -VIEW_RADIUS
    elif dx > VIEW_RADIUS:
        dx = VIEW_RADIUS
    if dy < -VIEW_RADIUS:
        dy = -VIEW_RADIUS
    elif dy > VIEW_RADIUS:
        dy = VIEW_RADIUS
    return (dx + VIEW_RADIUS) * WINDOW + dy + VIEW_RADIUS


def state_offset(state: np.ndarray) -> np.ndarray:
    """Inverse of :func:`offset_state` on the window: state indices to offsets ``(..., 2)``."""
    state = np.asarray(state)
    return np.stack([state // WINDOW - VIEW_RADIUS, state % WINDOW - VIEW_RADIUS], axis=-1)


@kernel
def chebyshev(ax, ay, bx, by):
    """The number of king's moves between two cells."""
    return max(abs(bx - ax), abs(by - ay))


def within(neighbours, x: int, y: int, distance: int) -> list[tuple[int, int, int]]:
    """The ``(id, x, y)`` of ``neighbours`` at most ``distance`` king's moves (:func:`chebyshev`)
    from cell ``(x, y)``, in their order: a cheap cut, spelled out rather than a call per
    neighbour, before a rule looks at the few left."""
    low_x, high_x, low_y, high_y = x - distance, x + distance, y - distance, y + distance
    return [n for n in neighbours if low_x <= n[1] <= high_x and low_y <= n[2] <= high_y]


@kernel
def sees(ax, ay, bx, by):
    """Whether an agent at cell ``a`` sees cell ``b`` (within the egocentric window)."""
    return abs(bx - ax) <= VIEW_RADIUS and abs(by - ay) <= VIEW_RADIUS


@kernel
def target_x(x, action, width):
    """The column an action aims at; a move off the grid aims at the current cell. (Kernels
    spell the move table out as branches: numba indexes a tuple by a variable slowly.)"""
    if action == LEFT:
        return x - 1 if x > 0 else x
    if action == RIGHT:
        return x + 1 if x + 1 < width else x
    return x


@kernel
def target_y(y, action, height):
    """The row an action aims at; a move off the grid aims at the current cell."""
    if action == UP:
        return y - 1 if y > 0 else y
    if action == DOWN:
        return y + 1 if y + 1 < height else y
    return y


@kernel
def move_of(dx, dy):
    """The action whose displacement is ``(dx, dy)``; STAY for anything that is not one step."""
    if dx == 0:
        return UP if dy == -1 else DOWN if dy == 1 else STAY
    if dy == 0:
        return LEFT if dx == -1 else RIGHT if dx == 1 else STAY
    return STAY


def intended_cell(x: int, y: int, action: int, width: int, height: int) -> tuple[int, int]:
    """The cell an action aims at, as a pair (off the grid: the current cell)."""
    return target_x(x, action, width), target_y(y, action, height)
