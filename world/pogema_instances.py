"""POGEMA's published instances (its benchmark's one-shot MAPF sets) as MovingAI files: the four
families, where their converted files lie (``maps/pogema/<family>/``, ``maps/pogema/README.md``
names the source), POGEMA's grids and ``[row, col]`` cells turned into our rows and tasks, and the
instances of a family listed back from the files.

POGEMA's grid strings: ``#`` a wall; ``.`` a free cell; ``@`` (a start only), ``$`` (a goal only)
and ``!`` (neither) free cells too (its ``GridConfig.str_map_to_list``). A cell ``[row, col]`` is
our ``(x, y) = (col, row)``.

A family's instances are its ``.scen`` files in name order, each naming its map in its second
column (a map file beside it): one instance per map (the random maps, the mazes, the MovingAI
tiles: the ``.scen`` has the map's name) or many on one map (the warehouse:
``<map>-seed-<seed>.scen``).
"""

from dataclasses import dataclass
from pathlib import Path

from nnql_swarm.protocol.walls import FREE, WALL
from nnql_swarm.world.terrain import MapError, Task, read_map, read_scen

POGEMA_FREE = frozenset(".@$!")
POGEMA_WALL = "#"

INSTANCES = Path(__file__).resolve().parent.parent / "maps" / "pogema"
"""The converted instances in the repository."""


@dataclass(frozen=True)
class Family:
    """One of POGEMA's instance sets: its name here, its folder in the benchmark's
    ``algorithms/experiments/``, the agent counts of the published one-shot tables, the one-shot
    episode's step limit (``<family>-mapf.yaml``'s ``max_episode_steps``), the agent counts of
    the published lifelong tables and the lifelong episode's step limit (``<family>-lmapf.yaml``'s
    ``max_episode_steps``), and how many instances it has (of each kind)."""

    name: str
    source: str
    agents: tuple[int, ...]
    max_steps: int
    lifelong_agents: tuple[int, ...]
    lifelong_steps: int
    instances: int = 128


FAMILIES = {f.name: f for f in (
    Family("random", "01-random", (8, 32, 64), 128, (8, 32, 64), 256),
    Family("mazes", "02-mazes", (8, 32, 64), 128, (8, 32, 64), 128),
    Family("warehouse", "03-warehouse", (64, 128, 192), 128, (32, 128, 192), 256),
    Family("movingai", "04-movingai", (64, 128, 256), 256, (64, 128, 256), 256),
)}


def grid_rows(text: str, name: str = "<grid>") -> tuple[str, ...]:
    """A POGEMA grid string's rows, each ``.`` (free) and ``@`` (wall); ValueError on a
    character POGEMA does not read or rows of unequal length."""
    lines = text.split()
    rows = []
    for number, line in enumerate(lines, start=1):
        odd = set(line) - POGEMA_FREE - {POGEMA_WALL}
        if odd:
            raise ValueError(f"{name}: row {number} holds {''.join(sorted(odd))!r}, which POGEMA "
                             f"does not read")
        rows.append("".join(WALL if c == POGEMA_WALL else FREE for c in line))
    if not rows or len({len(r) for r in rows}) != 1:
        raise ValueError(f"{name}: the rows are not all of one length")
    return tuple(rows)


def tasks(agents_xy: list, targets_xy: list) -> tuple[Task, ...]:
    """POGEMA's starts and goals, ``[row, col]`` each, as ``(start_x, start_y, goal_x,
    goal_y)`` per agent."""
    if len(agents_xy) != len(targets_xy):
        raise ValueError(f"{len(agents_xy)} starts but {len(targets_xy)} goals")
    return tuple((int(s[1]), int(s[0]), int(g[1]), int(g[0]))
                 for s, g in zip(agents_xy, targets_xy))


def instance_stem(map_name: str, seed: int, maps_used: int) -> str:
    """The file name (without suffix) of an instance: its map's where the family has a map an
    instance, else the map's and the seed's."""
    return map_name if maps_used > 1 else f"{map_name}-seed-{seed:03d}"


@dataclass(frozen=True)
class Instance:
    """One instance: its name (its ``.scen`` file's stem), map and ``agents`` tasks."""

    name: str
    map_name: str
    rows: tuple[str, ...]
    tasks: tuple[Task, ...]


def scen_files(family: str, directory: Path = INSTANCES) -> list[Path]:
    """A family's ``.scen`` files in name order; MapError if there are none."""
    files = sorted((directory / family).glob("*.scen"))
    if not files:
        raise MapError(str(directory / family), 0, "holds no .scen file (POGEMA's instances: "
                                                   "maps/pogema/README.md)")
    return files


def read_instance(scen: Path, agents: int) -> Instance:
    """An instance of ``agents`` agents: the first lines of ``scen``, on the map its second
    column names (beside it). Raises MapError."""
    try:
        first = scen.read_text().splitlines()[1]
        map_name = first.split("\t")[1]
    except (OSError, UnicodeDecodeError, IndexError):
        raise MapError(str(scen), 2, "cannot be read, or names no map") from None
    rows = read_map(scen.parent / map_name)
    return Instance(scen.stem, map_name, rows, read_scen(scen, rows, agents))


# -- lifelong instances ------------------------------------------------------------------------
# A ``.goals`` file (ours; MovingAI has no lifelong format): ``lifelong 1``, ``map <file>``, then
# one tab-separated line per agent, ``start_x start_y`` and its goals in order, ``x y`` each.

Lifelong = tuple[str, tuple[tuple[int, int], ...], tuple[tuple[tuple[int, int], ...], ...]]
"""A lifelong instance: its map's file name, each agent's start and each agent's goals."""


def format_goals(map_name: str, starts, goals) -> str:
    lines = ["lifelong 1", f"map {map_name}"]
    for start, sequence in zip(starts, goals):
        lines.append("\t".join(str(v) for cell in (start, *sequence) for v in cell))
    return "\n".join(lines) + "\n"


def parse_goals(text: str, rows: tuple[str, ...], name: str = "<goals>") -> Lifelong:
    """A ``.goals`` file checked against its map: every cell on it and free, no two starts on
    one cell, every agent at least one goal. Raises MapError."""
    lines = text.splitlines()
    if len(lines) < 2 or lines[0] != "lifelong 1" or not lines[1].startswith("map "):
        raise MapError(name, 1, "expected 'lifelong 1', then 'map <file>'")
    height, width = len(rows), len(rows[0])
    starts, goals = [], []
    for number, line in enumerate(lines[2:], start=3):
        try:
            values = [int(v) for v in line.split("\t")]
        except ValueError:
            raise MapError(name, number, "expected whole numbers, tab-separated") from None
        if len(values) < 4 or len(values) % 2:
            raise MapError(name, number, "expected a start and at least one goal, x y each")
        cells = tuple(zip(values[::2], values[1::2]))
        for x, y in cells:
            if not (0 <= x < width and 0 <= y < height) or rows[y][x] != FREE:
                raise MapError(name, number, f"({x}, {y}) is off the map or a wall")
        if cells[0] in starts:
            raise MapError(name, number, f"the start {cells[0]} is another agent's")
        starts.append(cells[0])
        goals.append(cells[1:])
    return lines[1][4:], tuple(starts), tuple(goals)


def lifelong_instance(path: str | Path, rows: tuple[str, ...], agents: int) -> dict:
    """The config fields of ``--goals FILE`` for a run of ``agents`` agents on the map ``rows``:
    the file's first ``agents`` agents' starts and first goals (``scenario``, every episode's),
    and the goals listed after those (``goal_lists``). Raises MapError."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as error:
        raise MapError(str(path), 0, f"cannot be read ({error.__class__.__name__})") from None
    _, starts, goals = parse_goals(text, rows, str(path))
    if len(starts) < agents:
        raise MapError(str(path), 0, f"lists {len(starts)} agents, not {agents}")
    return {"scenario": tuple((*start, *sequence[0]) for start, sequence
                              in zip(starts[:agents], goals[:agents])),
            "goal_lists": tuple(tuple(v for cell in sequence[1:] for v in cell)
                                for sequence in goals[:agents])}


@dataclass(frozen=True)
class LifelongInstance:
    """One lifelong instance of ``agents`` agents: its name (its ``.goals`` file's stem), map,
    and the config fields ``scenario`` and ``goal_lists`` (:func:`lifelong_instance`)."""

    name: str
    map_name: str
    rows: tuple[str, ...]
    scenario: tuple[Task, ...]
    goal_lists: tuple[tuple[int, ...], ...]


def goals_files(family: str, directory: Path = INSTANCES) -> list[Path]:
    """A family's lifelong instances (``<family>/lifelong/*.goals``) in name order; MapError if
    there are none."""
    files = sorted((directory / family / "lifelong").glob("*.goals"))
    if not files:
        raise MapError(str(directory / family / "lifelong"), 0, "holds no .goals file (POGEMA's "
                                                                "instances: maps/pogema/README.md)")
    return files


def read_lifelong(path: Path, agents: int) -> LifelongInstance:
    """The lifelong instance of ``agents`` agents in ``path``, on the map its second line names
    (in the family's folder, above ``lifelong/``). Raises MapError."""
    try:
        second = path.read_text().splitlines()[1]
    except (OSError, UnicodeDecodeError, IndexError):
        raise MapError(str(path), 2, "cannot be read, or names no map") from None
    if not second.startswith("map "):
        raise MapError(str(path), 2, "expected 'map <file>'")
    map_name = second[4:]
    rows = read_map(path.parent.parent / map_name)
    fields = lifelong_instance(path, rows, agents)
    return LifelongInstance(path.stem, map_name, rows, fields["scenario"], fields["goal_lists"])
