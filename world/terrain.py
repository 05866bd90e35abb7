"""Maps and scenarios as input: the MovingAI ``.map`` and ``.scen`` formats, and seeded generators
of the field's map families (random, maze, warehouse).

A map reaches every process inside the run's config (``protocol.config.SwarmConfig.map_rows``:
one string per row, ``.`` free and ``@`` wall; ``protocol.walls`` reads its walls), never as a file: the launcher reads or generates
it once, ``config.json`` holds it, and the world, the agents, the simulator and ``--resume`` read
it from there. A scenario (``SwarmConfig.scenario``: ``(start_x, start_y, goal_x, goal_y)`` per
agent) fixes every episode's starts and goals.

The ``.map`` format: four header lines, ``type <name>``, ``height H``, ``width W``, ``map``, then H
rows of W characters; ``.`` and ``G`` are passable, every other character is a wall; ``(0, 0)`` is
the top-left cell, ``x`` the column and ``y`` the row. The ``.scen`` format: ``version 1``, then one
tab-separated line per agent, ``bucket map width height start_x start_y goal_x goal_y
optimal_length``; a k-agent instance is the first k lines. The ``optimal_length`` we write is the
4-connected shortest path (MovingAI's is octile); it is not read back.

Every error names the file and line and says what is wrong (:class:`MapError`).
"""

from collections import deque
from functools import lru_cache
from pathlib import Path

import numpy as np

from nnql_swarm.protocol.seeding import MAP_STREAM, stream_rng
from nnql_swarm.protocol.walls import FREE, WALL, map_walls, open_cells

PASSABLE = frozenset(".G")
"""The passable characters of a MovingAI map; every other character is a wall."""

MAX_SIDE = 1024
"""The largest map side (``protocol.messages.MAX_GRID``: coordinates are below it)."""

GENERATORS = ("random", "maze", "warehouse")
WAREHOUSE_SIZE = (46, 33)
"""The warehouse's default size, width x height: POGEMA's 33 x 46 cells."""


class MapError(ValueError):
    """A malformed map or scenario: ``<file>:<line>: what is wrong`` (line 0: the file as a
    whole)."""

    def __init__(self, name: str, line: int, message: str) -> None:
        super().__init__(f"{name}:{line}: {message}" if line else f"{name}: {message}")


# -- the .map format ---------------------------------------------------------------------------


def parse_map(text: str, name: str = "<map>") -> tuple[str, ...]:
    """A ``.map`` file's rows, each normalised to ``.`` (free) and ``@`` (wall)."""
    lines = text.splitlines()
    sides: dict[str, int] = {}  # height and width
    expected = ("type", "height", "width", "map")
    for number, key in enumerate(expected, start=1):
        if number > len(lines):
            raise MapError(name, number, f"the header ends early: expected '{key}'")
        words = lines[number - 1].split()
        if not words or words[0].lower() != key:
            raise MapError(name, number, f"expected '{key}', found {lines[number - 1].strip()!r}")
        if key == "map":
            if len(words) != 1:
                raise MapError(name, number, "expected 'map' alone on its line")
            continue
        if len(words) != 2:
            raise MapError(name, number, f"expected '{key} <value>'")
        if key in ("height", "width"):
            try:
                value = int(words[1])
            except ValueError:
                raise MapError(name, number,
                               f"{key} must be a whole number, not {words[1]!r}") from None
            if not 2 <= value <= MAX_SIDE:
                raise MapError(name, number, f"{key} must be 2..{MAX_SIDE}, not {value}")
            sides[key] = value
    height, width = sides["height"], sides["width"]
    body = lines[4:]
    while body and not body[-1].strip():
        body.pop()  # trailing blank lines
    if len(body) != height:
        line = 5 + min(len(body), height)
        raise MapError(name, line, f"the header says {height} rows, the map has {len(body)}")
    rows = []
    for number, row in enumerate(body, start=5):
        if len(row) != width:
            raise MapError(name, number, f"the header says {width} cells a row, this row has "
                                         f"{len(row)}")
        rows.append("".join(FREE if c in PASSABLE else WALL for c in row))
    return tuple(rows)


def format_map(rows: tuple[str, ...] | list[str]) -> str:
    """A map's ``.map`` text (``type octile``)."""
    return f"type octile\nheight {len(rows)}\nwidth {len(rows[0])}\nmap\n" + "\n".join(rows) + "\n"


def read_map(path: str | Path) -> tuple[str, ...]:
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise MapError(str(path), 0, f"cannot be read ({error.__class__.__name__})") from None
    return parse_map(text, str(path))


# -- the .scen format --------------------------------------------------------------------------

Task = tuple[int, int, int, int]
"""One agent's ``(start_x, start_y, goal_x, goal_y)``."""


def parse_scen(text: str, rows: tuple[str, ...], agents: int,
               name: str = "<scen>") -> tuple[Task, ...]:
    """The first ``agents`` tasks of a ``.scen`` file, checked against the map: every cell on it
    and free, no two starts and no two goals on one cell (a goal may be another agent's start, as
    in MovingAI's scenarios), each goal reachable from its start."""
    height, width = len(rows), len(rows[0])
    lines = text.splitlines()
    if not lines or lines[0].split() != ["version", "1"]:
        found = (lines[0] if lines else "").strip()
        raise MapError(name, 1, f"expected 'version 1', found {found!r}")
    tasks: list[Task] = []
    seen: dict[tuple[str, int, int], int] = {}  # (start or goal, x, y) -> its line
    region = regions(rows)
    number = 1
    for number, line in enumerate(lines[1:], start=2):
        if len(tasks) == agents:
            break
        if not line.strip():
            continue
        columns = line.rstrip("\r\n").split("\t")
        if len(columns) != 9:
            raise MapError(name, number, f"expected 9 tab-separated columns (bucket map width "
                                         f"height start_x start_y goal_x goal_y optimal_length), "
                                         f"found {len(columns)}")
        try:
            w, h, sx, sy, gx, gy = (int(v) for v in columns[2:8])
            float(columns[8])
            int(columns[0])
        except ValueError:
            raise MapError(name, number, "bucket, width, height and the cells must be whole "
                                         "numbers, the optimal length a number") from None
        if (w, h) != (width, height):
            raise MapError(name, number, f"the scenario is for a {w}x{h} map, the map is "
                                         f"{width}x{height}")
        for what, (cx, cy) in (("start", (sx, sy)), ("goal", (gx, gy))):
            if not (0 <= cx < width and 0 <= cy < height):
                raise MapError(name, number, f"the {what} ({cx}, {cy}) is off the "
                                             f"{width}x{height} map")
            if rows[cy][cx] != FREE:
                raise MapError(name, number, f"the {what} ({cx}, {cy}) is a wall")
            if (what, cx, cy) in seen:
                raise MapError(name, number, f"the {what} ({cx}, {cy}) is also the {what} on "
                                             f"line {seen[what, cx, cy]}: no two agents start, "
                                             f"or end, on one cell")
            seen[what, cx, cy] = number
        if region[sy, sx] != region[gy, gx]:
            raise MapError(name, number, f"the goal ({gx}, {gy}) cannot be reached from the "
                                         f"start ({sx}, {sy})")
        tasks.append((sx, sy, gx, gy))
    if len(tasks) < agents:
        raise MapError(name, number, f"{agents} agents need {agents} scenario lines, the file "
                                     f"has {len(tasks)}")
    return tuple(tasks)


def read_scen(path: str | Path, rows: tuple[str, ...], agents: int) -> tuple[Task, ...]:
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise MapError(str(path), 0, f"cannot be read ({error.__class__.__name__})") from None
    return parse_scen(text, rows, agents, str(path))


def format_scen(rows: tuple[str, ...], tasks, map_name: str, lengths=None) -> str:
    """A ``.scen`` text of ``tasks``, bucket ``i // 10``, the optimal length 4-connected (each
    task's from ``lengths`` if given, else found here)."""
    height, width = len(rows), len(rows[0])
    lines = ["version 1"]
    for i, (sx, sy, gx, gy) in enumerate(tasks):
        length = distances(rows, gx, gy)[sy, sx] if lengths is None else lengths[i]
        lines.append("\t".join(str(v) for v in (i // 10, map_name, width, height, sx, sy, gx, gy,
                                                 f"{length:.8f}")))
    return "\n".join(lines) + "\n"


def distances(rows: tuple[str, ...], x: int, y: int) -> np.ndarray:
    """4-connected moves from every cell to ``(x, y)``, ``(H, W)``; -1 where unreachable."""
    height, width = len(rows), len(rows[0])
    out = np.full((height, width), -1, dtype=np.int64)
    out[y, x] = 0
    todo = deque([(x, y)])
    while todo:
        cx, cy = todo.popleft()
        for nx, ny in ((cx - 1, cy), (cx + 1, cy), (cx, cy - 1), (cx, cy + 1)):
            if 0 <= nx < width and 0 <= ny < height and out[ny, nx] < 0 and rows[ny][nx] == FREE:
                out[ny, nx] = out[cy, cx] + 1
                todo.append((nx, ny))
    return out


def regions(rows: tuple[str, ...]) -> np.ndarray:
    """Each cell's 4-connected free region, ``(H, W)``: a label from 0 for a free cell, -1 for a
    wall; two cells reach each other when their labels are equal."""
    height, width = len(rows), len(rows[0])
    out = np.full((height, width), -1, dtype=np.int64)
    label = 0
    for y in range(height):
        for x in range(width):
            if rows[y][x] != FREE or out[y, x] >= 0:
                continue
            out[y, x] = label
            todo = [(x, y)]
            while todo:
                cx, cy = todo.pop()
                for nx, ny in ((cx - 1, cy), (cx + 1, cy), (cx, cy - 1), (cx, cy + 1)):
                    if 0 <= nx < width and 0 <= ny < height and out[ny, nx] < 0 \
                            and rows[ny][nx] == FREE:
                        out[ny, nx] = label
                        todo.append((nx, ny))
            label += 1
    return out


# -- generators --------------------------------------------------------------------------------


def random_map(width: int, height: int, density: float,
               rng: np.random.Generator) -> tuple[str, ...]:
    """``round(density * W * H)`` walls on distinct cells drawn uniformly (POGEMA's random maps:
    17 to 21 cells a side, 20 % walls)."""
    walls = set(rng.choice(width * height, size=int(round(density * width * height)),
                           replace=False).tolist())
    return tuple("".join(WALL if y * width + x in walls else FREE for x in range(width))
                 for y in range(height))


def maze_map(width: int, height: int, rng: np.random.Generator) -> tuple[str, ...]:
    """A maze of corridors one cell wide: a depth-first spanning tree of the cells at even
    ``(x, y)``, each tree edge opening the wall between its two cells (a side of even length
    leaves its last line a wall)."""
    grid = [[WALL] * width for _ in range(height)]
    cols, rws = (width + 1) // 2, (height + 1) // 2
    seen = [[False] * cols for _ in range(rws)]
    start = (int(rng.integers(cols)), int(rng.integers(rws)))
    stack = [start]
    seen[start[1]][start[0]] = True
    grid[2 * start[1]][2 * start[0]] = FREE
    while stack:
        cx, cy = stack[-1]
        options = [(cx + dx, cy + dy) for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1))
                   if 0 <= cx + dx < cols and 0 <= cy + dy < rws and not seen[cy + dy][cx + dx]]
        if not options:
            stack.pop()
            continue
        nx, ny = options[int(rng.integers(len(options)))]
        seen[ny][nx] = True
        grid[2 * ny][2 * nx] = FREE
        grid[cy + ny][cx + nx] = FREE  # the wall between (2cx, 2cy) and (2nx, 2ny)
        stack.append((nx, ny))
    return tuple("".join(row) for row in grid)


def warehouse_map(width: int, height: int) -> tuple[str, ...]:
    """Shelves of 5 x 2 wall cells in a block pattern, one free column between shelves of a
    row and two free rows between rows of shelves, inside a free margin of at least 2 cells
    (at 46 x 33, POGEMA's warehouse size: 7 shelves a row, 7 rows of them)."""
    shelf_w, shelf_h, gap_x, gap_y, margin = 5, 2, 1, 2, 2
    nx = max(0, (width - 2 * margin + gap_x) // (shelf_w + gap_x))
    ny = max(0, (height - 2 * margin + gap_y) // (shelf_h + gap_y))
    used_x = nx * (shelf_w + gap_x) - gap_x
    used_y = ny * (shelf_h + gap_y) - gap_y
    left, top = (width - used_x) // 2, (height - used_y) // 2
    grid = [[FREE] * width for _ in range(height)]
    for j in range(ny):
        for i in range(nx):
            x0, y0 = left + i * (shelf_w + gap_x), top + j * (shelf_h + gap_y)
            for y in range(y0, y0 + shelf_h):
                for x in range(x0, x0 + shelf_w):
                    grid[y][x] = WALL
    return tuple("".join(row) for row in grid)


def generated(spec: str, seed: int) -> tuple[str, ...] | None:
    """The map a generator spec names, or None if ``spec`` names no generator (a file, then):
    ``random:WxH:P[:SEED]``, ``maze:WxH[:SEED]``, ``warehouse[:WxH]``; SEED defaults to
    ``seed`` (the run's), drawn through its own stream (``protocol.seeding.MAP_STREAM``).
    Raises ValueError on a malformed spec."""
    kind, _, rest = spec.partition(":")
    if kind not in GENERATORS:
        return None
    parts = rest.split(":") if rest else []
    usage = {"random": "random:WxH:P[:SEED], e.g. random:19x19:0.2",
             "maze": "maze:WxH[:SEED], e.g. maze:19x19",
             "warehouse": "warehouse[:WxH], e.g. warehouse:46x33"}[kind]
    try:
        if kind == "warehouse":
            if len(parts) > 1:
                raise ValueError
            width, height = _size(parts[0]) if parts else WAREHOUSE_SIZE
            return warehouse_map(width, height)
        wanted = 2 if kind == "random" else 1
        if not wanted <= len(parts) <= wanted + 1:
            raise ValueError
        width, height = _size(parts[0])
        if len(parts) > wanted:
            seed = int(parts[wanted])
            if seed < 0:
                raise ValueError
        rng = stream_rng(seed, MAP_STREAM, 0)
        if kind == "maze":
            return maze_map(width, height, rng)
        density = float(parts[1])
        if not 0 <= density <= 0.9:
            raise ValueError
        return random_map(width, height, density, rng)
    except ValueError:
        raise ValueError(f"--map {spec}: expected {usage} (sides 2..{MAX_SIDE}, "
                         f"density 0..0.9, seed >= 0)") from None


def _size(text: str) -> tuple[int, int]:
    width, height = (int(v) for v in text.lower().split("x"))
    if not (2 <= width <= MAX_SIDE and 2 <= height <= MAX_SIDE):
        raise ValueError
    return width, height


def load(spec: str, seed: int) -> tuple[str, ...]:
    """The rows of ``--map SPEC``: a generator's map, else a ``.map`` file's. Raises MapError /
    ValueError."""
    rows = generated(spec, seed)
    return rows if rows is not None else read_map(spec)


def draw_tasks(rows: tuple[str, ...], count: int, rng: np.random.Generator) -> tuple[Task, ...]:
    """``count`` tasks on ``2 * count`` distinct cells of the map's largest free region (as the
    swarm draws starts and goals): the tasks a ``.scen`` of the map holds."""
    width = len(rows[0])
    region = open_cells(width, len(rows), map_walls(rows))
    if 2 * count > len(region):
        raise ValueError(f"{count} tasks need {2 * count} free cells, the map's largest free "
                         f"region has {len(region)}")
    cells = rng.choice(region, size=2 * count, replace=False)
    return tuple((int(s % width), int(s // width), int(g % width), int(g // width))
                 for s, g in zip(cells[:count], cells[count:]))


@lru_cache(maxsize=64)
def run_map(spec: str, scen: str | None, seed: int, agents: int) -> dict:
    """The config fields of ``--map SPEC`` and ``--scen FILE`` for a run of ``agents`` agents
    and ``seed``: ``width``, ``height``, ``map_name``, ``map_rows`` and ``scenario``. Raises
    MapError (a file's fault, with its name and line) or ValueError."""
    rows = load(spec, seed)
    tasks = read_scen(scen, rows, agents) if scen else ()
    return {"width": len(rows[0]), "height": len(rows), "map_name": spec, "map_rows": rows,
            "scenario": tasks}
