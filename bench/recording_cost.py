#!/usr/bin/env python3
"""What Rerun recording costs the swarm: ticks per second with and without it, in the same run.

Each repeat runs the same config twice, recording off and on (alternating which goes first, so
drift in the machine's load hits both alike): a world process and one process per agent over
embedded Zenoh, exactly as ``launch/swarm.py`` starts them. Recording on means the full default
recording: the world logs every tick (``recording.world``), every agent logs its heat maps and
negotiation timing each episode (``recording.agent``), each process saves its part of ``run.rrd``.
The rate is ticks / seconds over every episode but the first (which includes start-up), from
``episodes.csv``; the figures are the medians over repeats (and the median of each repeat's
own off/on difference, which drift in the machine's load disturbs less); the merge into
``run.rrd`` after the run is timed separately. The grid grows with the agents
(``bench.harness.grid_side``: 11 x 11 for 8, 32 x 32 for 64). ``--in-process`` measures the one-process runner instead.

    python -m bench.recording_cost --agents 8 --repeats 5
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from bench.harness import (
    add_preset_option, grid_side, run_distributed, run_local, swarm_config,
)
from nnql_swarm.recording.merge import merge_parts

TARGET = 0.10
"""Recording may cost at most 10 % of the tick rate."""


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--in-process", action="store_true", help="the one-process runner instead")
    p.add_argument("--keep", type=Path, default=None, metavar="DIR",
                   help="keep the runs in this new folder (one per repeat and setting: the "
                        "recorded ones' run.rrd to open in the viewer), not a temporary one")
    add_preset_option(p)
    args = p.parse_args()
    if args.keep is not None and args.keep.exists():
        p.error(f"--keep {args.keep}: already there; name a new folder")
    config = swarm_config(args.preset, run_id="recording-cost", n_agents=args.agents,
                          episodes=args.episodes, max_steps=args.max_steps,
                          width=grid_side(args.agents), height=grid_side(args.agents))
    run = run_local if args.in_process else run_distributed
    rates: dict[bool, list[float]] = {False: [], True: []}
    merges, sizes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        if args.keep is not None:
            tmp = str(args.keep)
        for r in range(args.repeats):
            for record in ((False, True) if r % 2 == 0 else (True, False)):
                out = Path(tmp) / f"{r}-{'on' if record else 'off'}"
                rates[record].append(run(config, out, record))
                if record and not args.in_process:
                    start = time.perf_counter()
                    merged = merge_parts(out)
                    merges.append(time.perf_counter() - start)
                    sizes.append(merged.stat().st_size / 1e6 if merged else float("nan"))
                print(f"repeat {r}: recording {'on ' if record else 'off'} "
                      f"{rates[record][-1]:7.1f} ticks/s", file=sys.stderr, flush=True)
    off, on = statistics.median(rates[False]), statistics.median(rates[True])
    cost = 1 - on / off
    paired = statistics.median(1 - b / a for a, b in zip(rates[False], rates[True]))
    mode = "in-process" if args.in_process else "distributed"
    print(f"{args.agents} agents, {mode}, {args.episodes} episodes x {args.max_steps} steps, "
          f"median of {args.repeats}")
    print(f"  recording off: {off:7.1f} ticks/s  ({' '.join(f'{x:.0f}' for x in rates[False])})")
    print(f"  recording on:  {on:7.1f} ticks/s  ({' '.join(f'{x:.0f}' for x in rates[True])})")
    print(f"  cost: {100 * cost:.1f} % of the tick rate (target at most {100 * TARGET:.0f} %); "
          f"median of the paired repeats: {100 * paired:.1f} %")
    if merges:
        print(f"  merge into run.rrd after the run: median {statistics.median(merges):.2f} s, "
              f"{statistics.median(sizes):.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
