#!/usr/bin/env python3
"""Convert POGEMA's published instance sets into MovingAI files (world.pogema_instances).

    python launch/pogema_import.py pogema-benchmark/algorithms/experiments --out maps/pogema

reads, for each family, the benchmark's ``maps.yaml`` (the grids), ``<family>-mapf.yaml`` (the
one-shot instances: ``scenarios``, each a ``map_name``, a ``seed`` and the ``agents_xy`` and
``targets_xy`` of its largest agent count, ``[row, col]`` each) and ``<family>-lmapf.yaml`` (the
lifelong instances: the same, each agent's ``targets_xy`` a sequence of goals), and writes into
``<out>/<family>/`` one ``.map`` per grid, one ``.scen`` per one-shot instance and, into
``lifelong/``, one ``.goals`` per lifelong instance (``world.pogema_instances.format_goals``). Every file
written is read back and checked (starts and goals on free cells, distinct, reachable). Needs
PyYAML (the project's ``pogema`` extra).
"""

import sys
from pathlib import Path

import numpy as np

from nnql_swarm.protocol.walls import map_walls, path_lengths
from nnql_swarm.launch.cli import OneLineParser, comma_choices
from nnql_swarm.world import terrain as maps, pogema_instances as pogema


def build_parser() -> OneLineParser:
    p = OneLineParser(description=__doc__.split("\n\n")[0])
    p.add_argument("source", type=Path, help="the algorithms/experiments folder of "
                   "CognitiveAISystems/pogema-benchmark at commit 3303133")
    p.add_argument("--out", type=Path, default=pogema.INSTANCES,
                   help="where the families' folders go (default: the repository's maps/pogema)")
    p.add_argument("--families", type=comma_choices(tuple(pogema.FAMILIES), "families"),
                   default=tuple(pogema.FAMILIES), metavar="LIST",
                   help=f"from {','.join(pogema.FAMILIES)} (default: all)")
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    try:
        import yaml
    except ImportError:
        p.error("reading POGEMA's yaml files needs PyYAML (pip install pyyaml, or the "
                "project's 'pogema' extra)")
    loader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

    def load(path: Path) -> dict:
        try:
            with open(path) as f:
                return yaml.load(f, Loader=loader)
        except OSError as error:
            p.error(f"{path}: cannot be read ({error.__class__.__name__})")
        except yaml.YAMLError as error:
            p.error(f"{path}: not yaml ({str(error).splitlines()[0]})")

    for name in args.families:
        family = pogema.FAMILIES[name]
        folder = args.source / family.source
        try:
            grids = {k: pogema.grid_rows(v, k) for k, v in load(folder / "maps.yaml").items()}
            one_shot = load(folder / f"{family.source}-mapf.yaml")["scenarios"]
            lifelong = load(folder / f"{family.source}-lmapf.yaml")["scenarios"]
            if len(one_shot) != family.instances or len(lifelong) != family.instances:
                raise ValueError(f"{folder}: {len(one_shot)} one-shot and {len(lifelong)} "
                                 f"lifelong instances, not {family.instances}")
            written = write_family(args.out / name, grids, one_shot, lifelong)
        except (KeyError, TypeError, ValueError) as error:
            p.error(f"{name}: {error}")
        print(f"{name}: {written}", file=sys.stderr)
    return 0


def write_family(out: Path, grids: dict, one_shot: dict, lifelong: dict) -> str:
    """Write a family's maps, one-shot and lifelong instances into ``out``; each read back."""
    (out / "lifelong").mkdir(parents=True, exist_ok=True)
    used = sorted({s["map_name"] for s in one_shot.values()})
    for map_name in used:
        (out / f"{map_name}.map").write_text(maps.format_map(grids[map_name]))
    for scenario in one_shot.values():
        map_name, rows = scenario["map_name"], grids[scenario["map_name"]]
        stem = pogema.instance_stem(map_name, scenario["seed"], len(used))
        tasks = pogema.tasks(scenario["agents_xy"], scenario["targets_xy"])
        scen = out / f"{stem}.scen"
        unmeasured = maps.format_scen(rows, tasks, f"{map_name}.map", [0] * len(tasks))
        maps.parse_scen(unmeasured, rows, len(tasks), str(scen))  # on the map, distinct, reachable
        cells = np.array(tasks, dtype=np.int64)
        lengths = path_lengths(len(rows[0]), len(rows), map_walls(rows), cells[:, :2],
                               cells[:, 2:])
        scen.write_text(maps.format_scen(rows, tasks, f"{map_name}.map", lengths))
        assert pogema.read_instance(scen, len(tasks)).tasks == tasks
    for scenario in lifelong.values():
        map_name, rows = scenario["map_name"], grids[scenario["map_name"]]
        stem = pogema.instance_stem(map_name, scenario["seed"], len(used))
        starts = [(int(c), int(r)) for r, c in scenario["agents_xy"]]
        goals = [[(int(c), int(r)) for r, c in sequence] for sequence in scenario["targets_xy"]]
        path = out / "lifelong" / f"{stem}.goals"
        path.write_text(pogema.format_goals(f"{map_name}.map", starts, goals))
        pogema.parse_goals(path.read_text(), rows, str(path))
    agents = len(next(iter(one_shot.values()))["agents_xy"])
    return (f"{len(used)} maps, {len(one_shot)} one-shot instances of {agents} agents, "
            f"{len(lifelong)} lifelong")


if __name__ == "__main__":
    sys.exit(main())
