#!/usr/bin/env python3
"""Write a generated map and its scenario in the MovingAI formats (world.terrain).

    python launch/maps.py random:19x19:0.2 --seed 0 --out maps/random-19x19-20-s0

writes ``<out>.map`` and ``<out>.scen`` (``--tasks`` lines, 64 by default: starts and goals on
distinct cells of the map's largest free region, drawn from the seed; the optimal length is the
4-connected shortest path).
"""

import argparse
import sys
from pathlib import Path

from nnql_swarm.world import terrain as maps
from nnql_swarm.protocol.seeding import MAP_STREAM, stream_rng
from nnql_swarm.launch.cli import OneLineParser


def build_parser() -> OneLineParser:
    p = OneLineParser(description=__doc__.split("\n\n")[0])
    p.add_argument("spec", help="random:WxH:P[:SEED], maze:WxH[:SEED] or warehouse[:WxH]")
    p.add_argument("--seed", type=int, default=0, help="the map's seed (unless the spec has "
                   "one) and the scenario's (default: 0)")
    p.add_argument("--tasks", type=int, default=64, help="scenario lines (default: 64)")
    p.add_argument("--out", type=Path, required=True, help="path of the files without suffix: writes OUT.map and "
                   "OUT.scen")
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    try:
        rows = maps.generated(args.spec, args.seed)
        if rows is None:
            p.error(f"{args.spec!r} names no generator ({', '.join(maps.GENERATORS)})")
        tasks = maps.draw_tasks(rows, args.tasks, stream_rng(args.seed, MAP_STREAM, 1))
    except ValueError as error:
        p.error(str(error))
    args.out.parent.mkdir(parents=True, exist_ok=True)
    map_file = args.out.with_name(args.out.name + ".map")
    map_file.write_text(maps.format_map(rows))
    args.out.with_name(args.out.name + ".scen").write_text(
        maps.format_scen(rows, tasks, map_file.name))
    print(f"{map_file} and .scen: {len(rows[0])}x{len(rows)}, "
          f"{sum(r.count(maps.WALL) for r in rows)} walls, {len(tasks)} tasks", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
