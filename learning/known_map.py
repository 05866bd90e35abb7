"""What an agent knows of the walls, and the way to its goal on that map: kernel functions.

The environment stays unknown to a learner: it knows a wall once the wall has been within its
view (``protocol.actions.sees``: 10 cells along each axis) from a cell it stood on, and it keeps
what it has seen for the rest of the run. The world sends no walls: every process has the run's
map (``protocol.walls``) and each agent derives what it saw from that map and its own positions,
which is what walls carried in its view would tell it.

On the known map (the unknown taken as free) a breadth-first *distance field* to the goal gives
the agent's path length ``d`` and the *waypoint*, the next cell of a shortest path. Destination
seeking reads them (``learning.learner``: ``LP_DS_STATE``, ``LP_DS_REWARD``). With the detour
(``LP_DETOUR``) the field also goes around the arrived agents the agent has seen within reach in
this episode (they stay there until it ends), unless they cut it off its goal. The field is worked
out again only when the goal changes, a new wall is seen or a newly arrived agent is taken.

An agent reads the distances of its cell, the cells next to it and the cell it came from, all at
most one step farther from the goal than its own. So the search is *lazy*: it stops once every
cell at most one step farther than the agent's has its distance, and goes on from where it
stopped when the agent comes to a cell farther out (:func:`grow_field`). A cell the search has
not reached reads -1, as a cell cut off does; no reading ever asks for one. The distances read
are those of the whole field, and the search visits about a third of the cells (64 agents on a
32 x 32 grid, the default preset: docs/performance.md).

One buffer of integers per agent (``wmap``, :func:`map_size`): ``MAP_GOAL`` (the goal cell the
field is for, -1 when stale), ``MAP_KNOWN`` (walls known), ``MAP_PARKED`` (arrived agents taken),
``MAP_CUT`` (whether they cut the agent off, so the field ignores them), ``MAP_PENDING`` (see
:func:`see_parked`), the search's queue ``MAP_HEAD`` and ``MAP_TAIL`` and whether it goes
around the arrived agents taken (``MAP_AROUND``), then per cell (``y * W + x``) whether it is a
known wall, its distance to the goal (-1 where cut off or not reached yet), the search's queue,
whether an arrived agent taken stands there, and the list of those cells.
"""

import numpy as np

from nnql_swarm.protocol.actions import (
    DOWN, LEFT, N_ACTIONS, RIGHT, STAY, UP, target_x, target_y,
)
from nnql_swarm.protocol.jit import kernel

WHOLE_MAP = 1 << 20
"""The sight of an agent that knows every wall of the map (``--map-known``): farther than any
grid is wide."""

MAP_GOAL, MAP_KNOWN, MAP_PARKED, MAP_CUT, MAP_PENDING = 0, 1, 2, 3, 4
MAP_HEAD, MAP_TAIL, MAP_AROUND = 5, 6, 7
MAP_HEADER = 8
NOTHING_PENDING = 1 << 30
SECTIONS = 5
"""Per cell: known wall, distance, queue, arrived agent planned around, and the list of those."""


def map_size(width: int, height: int) -> int:
    """The length of an agent's ``wmap`` on a ``width x height`` grid."""
    return MAP_HEADER + SECTIONS * width * height


def fresh_map(wmap) -> None:
    """Forget everything (a buffer of :func:`map_size`): no wall known, no arrived agent, no
    field (no cell has a distance)."""
    size = len(wmap)
    cells = (size - MAP_HEADER) // SECTIONS
    distances = slice(MAP_HEADER + cells, MAP_HEADER + 2 * cells)
    if isinstance(wmap, np.ndarray):
        wmap[:] = 0
        wmap[distances] = -1
    else:
        wmap[:] = [0] * size
        wmap[distances] = [-1] * cells
    wmap[MAP_GOAL] = -1
    wmap[MAP_PENDING] = NOTHING_PENDING


def known_cells(wmap, width: int, height: int) -> list[int]:
    """The known walls' cells (``y * W + x``, ascending): what a checkpoint keeps."""
    if isinstance(wmap, np.ndarray):
        return np.flatnonzero(wmap[MAP_HEADER:MAP_HEADER + width * height]).tolist()
    return [c for c in range(width * height) if wmap[MAP_HEADER + c] != 0]


def restore_known(wmap, cells, width: int, height: int) -> None:
    """Take a checkpoint's known walls (:func:`known_cells`) into a fresh buffer."""
    fresh_map(wmap)
    for c in cells:
        if not 0 <= c < width * height:
            raise ValueError(f"known wall {c} outside the grid")
        if wmap[MAP_HEADER + c] == 0:
            wmap[MAP_HEADER + c] = 1
            wmap[MAP_KNOWN] += 1


def check_cell_order(walls) -> None:
    """Refuse walls (``(x, y)`` pairs) that are not in cell order (``y * W + x``, the order
    ``protocol.walls`` gives them in): :func:`see_walls` finds the rows in view by bisection."""
    keys = [(y, x) for x, y in walls]
    if keys != sorted(keys):
        raise ValueError("the run's walls must come in cell order (y * W + x)")


@kernel
def see_walls(wmap, wall_x, wall_y, first, last, ox, oy, width, sight):
    """Mark the walls ``first .. last - 1`` (cells ``wall_x[k], wall_y[k]``, in cell order)
    within ``sight`` of ``(ox, oy)`` (Chebyshev: ``VIEW_RADIUS``, or :data:`WHOLE_MAP` where the
    agent knows the map, ``--map-known``) known; a wall newly known makes the distance field
    stale."""
    if wmap[MAP_KNOWN] == last - first:
        return
    low = first  # the first wall in a row in view: rows are in order
    high = last
    while low < high:
        mid = (low + high) // 2
        if wall_y[mid] < oy - sight:
            low = mid + 1
        else:
            high = mid
    for k in range(low, last):
        wy = wall_y[k]
        if wy > oy + sight:
            break
        wx = wall_x[k]
        if ox - sight <= wx <= ox + sight:
            at = MAP_HEADER + wy * width + wx
            if wmap[at] == 0:
                wmap[at] = 1
                wmap[MAP_KNOWN] += 1
                wmap[MAP_GOAL] = -1


@kernel
def see_parked(wmap, nb, m, ox, oy, around, starts, width, height):
    """Take the arrived agents among the neighbour rows ``nb`` (``learning.fields.NB_*``) within
    ``around`` cells (Chebyshev; -1: none) as obstacles the field plans around, for the rest of
    the episode (an arrived agent stays on its goal); ``starts``: a new episode, none taken yet. A
    newly taken one is *pending* (``MAP_PENDING``: the least distance of those cells in the
    current field): :func:`plan_field` plans around it once the agent comes near enough for it
    to change a distance it reads."""
    cells = width * height
    flag = MAP_HEADER + 3 * cells
    listed = MAP_HEADER + 4 * cells
    if starts and wmap[MAP_PARKED] > 0:
        for k in range(wmap[MAP_PARKED]):
            wmap[flag + wmap[listed + k]] = 0
        wmap[MAP_PARKED] = 0
        wmap[MAP_GOAL] = -1
    if around < 0:
        return
    for j in range(m):
        if nb[j][8] == 0:  # NB_PARKED
            continue
        jx = nb[j][1]  # NB_X, NB_Y
        jy = nb[j][2]
        if max(abs(jx - ox), abs(jy - oy)) > around:
            continue
        cell = jy * width + jx
        if wmap[flag + cell] == 0:
            wmap[flag + cell] = 1
            wmap[listed + wmap[MAP_PARKED]] = cell
            wmap[MAP_PARKED] += 1
            if wmap[MAP_GOAL] >= 0 and wmap[MAP_CUT] == 0:  # (cut off: the field ignores them)
                wmap[MAP_AROUND] = 1  # the search goes around it if it has not reached it yet
                d = wmap[MAP_HEADER + cells + cell]
                if 0 <= d < wmap[MAP_PENDING]:
                    wmap[MAP_PENDING] = d


@kernel
def plan_field(wmap, ox, oy, gx, gy, width, height):
    """Make the distance field to the goal ``(gx, gy)`` current at ``(ox, oy)``: around the known
    walls and the parked agents taken (:func:`see_parked`; around the walls alone where those cut
    ``(ox, oy)`` off the goal), 4-connected, grown as far as the agent reads it
    (:func:`grow_field`).

    A field that does not plan around the pending parked agents yet (:func:`see_parked`) is as
    good as current while each of them is at least 2 steps farther from the goal than the agent:
    a cell's distance depends only on the cells nearer the goal, and the agent reads the
    distances of its cell, the cells next to it and the cell it came from."""
    goal = gy * width + gx
    at = oy * width + ox
    if wmap[MAP_GOAL] == goal:
        here = grow_field(wmap, at, width, height)
        if 0 <= here and here + 2 <= wmap[MAP_PENDING]:
            return
    wmap[MAP_PENDING] = NOTHING_PENDING
    start_field(wmap, goal, width, height, wmap[MAP_PARKED] > 0)
    wmap[MAP_CUT] = 0
    if grow_field(wmap, at, width, height) < 0 and wmap[MAP_PARKED] > 0:
        start_field(wmap, goal, width, height, False)
        grow_field(wmap, at, width, height)
        wmap[MAP_CUT] = 1
    wmap[MAP_GOAL] = goal


@kernel
def start_field(wmap, goal, width, height, around):
    """Start the breadth-first search from ``goal``: no distance known but the goal's; it goes
    around the arrived agents taken if ``around``. Only the cells the last search reached have a
    distance to forget: they are those of its queue (:func:`fresh_map` leaves none)."""
    cells = width * height
    dist = MAP_HEADER + cells
    queue = MAP_HEADER + 2 * cells
    for k in range(wmap[MAP_TAIL]):
        wmap[dist + wmap[queue + k]] = -1
    wmap[dist + goal] = 0
    wmap[queue] = goal
    wmap[MAP_HEAD] = 0
    wmap[MAP_TAIL] = 1
    wmap[MAP_AROUND] = 1 if around else 0


@kernel
def grow_field(wmap, at, width, height):
    """Go on with the breadth-first search (:func:`start_field`) until cell ``at`` has its
    distance and so has every cell at most one step farther (or every cell reachable has; every
    one, for ``at`` -1); returns ``at``'s distance, -1 where it is cut off. A cell is entered
    unless it is a known wall, or an arrived agent taken where the search goes around them
    (``MAP_AROUND``). The four neighbours are spelled out: it is the agent's costliest step in
    plain Python."""
    cells = width * height
    dist = MAP_HEADER + cells
    queue = MAP_HEADER + 2 * cells
    flag = MAP_HEADER + 3 * cells
    around = wmap[MAP_AROUND] != 0
    head = wmap[MAP_HEAD]
    tail = wmap[MAP_TAIL]
    while head < tail:
        c = wmap[queue + head]
        here = wmap[dist + at] if at >= 0 else -1
        if 0 <= here < wmap[dist + c]:  # every cell nearer than here + 2 has its distance
            break
        head += 1
        d = wmap[dist + c] + 1
        cx = c % width
        n = c - 1
        if cx > 0 and wmap[dist + n] == -1 and wmap[MAP_HEADER + n] == 0 \
                and not (around and wmap[flag + n] != 0):
            wmap[dist + n] = d
            wmap[queue + tail] = n
            tail += 1
        n = c + 1
        if cx < width - 1 and wmap[dist + n] == -1 and wmap[MAP_HEADER + n] == 0 \
                and not (around and wmap[flag + n] != 0):
            wmap[dist + n] = d
            wmap[queue + tail] = n
            tail += 1
        n = c - width
        if c >= width and wmap[dist + n] == -1 and wmap[MAP_HEADER + n] == 0 \
                and not (around and wmap[flag + n] != 0):
            wmap[dist + n] = d
            wmap[queue + tail] = n
            tail += 1
        n = c + width
        if n < cells and wmap[dist + n] == -1 and wmap[MAP_HEADER + n] == 0 \
                and not (around and wmap[flag + n] != 0):
            wmap[dist + n] = d
            wmap[queue + tail] = n
            tail += 1
    wmap[MAP_HEAD] = head
    wmap[MAP_TAIL] = tail
    return wmap[dist + at] if at >= 0 else -1


@kernel
def track(wmap, wall_x, wall_y, first, last, ox, oy, gx, gy, width, height, nb, m, around,
          starts, sight):
    """An observation at ``(ox, oy)`` with goal ``(gx, gy)`` (``starts``: the first of an
    episode): the walls within ``sight`` learned (:func:`see_walls`), the arrived neighbours
    within ``around`` taken (-1: none), the distance field made current."""
    see_walls(wmap, wall_x, wall_y, first, last, ox, oy, width, sight)
    see_parked(wmap, nb, m, ox, oy, around, starts, width, height)
    plan_field(wmap, ox, oy, gx, gy, width, height)


@kernel
def path_length(wmap, x, y, width, height):
    """The cell's distance to the goal on the known map (-1 if cut off; the field current and
    grown past it: the agent's cell, a cell next to it, or one nearer the goal)."""
    return wmap[MAP_HEADER + width * height + y * width + x]


@kernel
def progress_moves(wmap, x, y, width, height):
    """The moves that bring ``(x, y)`` one step nearer the goal on the known map, as bits (bit
    ``a``: action ``a``); 0 on the goal."""
    cells = width * height
    dist = MAP_HEADER + cells
    here = wmap[dist + y * width + x]
    mask = 0
    if here <= 0:
        return 0
    for a in range(4):
        nc = target_y(y, a, height) * width + target_x(x, a, width)
        if wmap[dist + nc] == here - 1 and wmap[dist + nc] >= 0:
            mask |= 1 << a
    return mask


@kernel
def waypoint_move(wmap, x, y, gx, gy, width, height):
    """The first move of the agent's shortest path on the known map: of the moves that bring it
    nearer (:func:`progress_moves`), the one along the axis where the goal is farther (the
    vertical one on a diagonal), then the first in action order; STAY on the goal."""
    mask = progress_moves(wmap, x, y, width, height)
    if mask == 0:
        return STAY
    horizontal = abs(gx - x) > abs(gy - y)
    best = STAY
    for a in range(4):
        if (mask >> a) & 1 == 0:
            continue
        if best == STAY:
            best = a
        elif horizontal and (a == LEFT or a == RIGHT) and (best == UP or best == DOWN):
            best = a
    return best


assert (UP, DOWN, LEFT, RIGHT, STAY) == (0, 1, 2, 3, 4) and N_ACTIONS == 5
