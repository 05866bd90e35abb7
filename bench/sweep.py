#!/usr/bin/env python3
"""Seconds for a swarm sweep on the simulator: 8 agents x 500 episodes x 10 seeds x {QL, nnQL}.

The paper's QL and nnQL presets (the slowest learners, so the longest episodes) for every seed,
played by ``experiment.swarm_experiment.run_experiment`` in one batch over the cores. The kernel is loaded
(or compiled) by an untimed warm-up; each repeat's wall time is printed, then the median against
the 20 s target, and the runs are checked to give the same episodes every time.

    python -m bench.sweep
    python -m bench.sweep --repeats 5 --workers 1
"""

import argparse
import os
import statistics
import sys
import time

import numpy as np

from nnql_swarm.experiment.swarm_experiment import SwarmExperiment, run_experiment

TARGET_SECONDS = 20.0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    p.add_argument("--variants", default="ql,nnql")
    args = p.parse_args()
    sweep = SwarmExperiment(seeds=10, episodes=500, variants=tuple(args.variants.split(",")))
    run_experiment(SwarmExperiment(seeds=1, episodes=2, variants=sweep.variants), args.workers)
    print(f"sweep: {sweep.agents} agents x {sweep.episodes} episodes x {sweep.seeds} seeds x "
          f"{{{', '.join(sweep.variants)}}}, {args.workers} thread(s), load average "
          f"{os.getloadavg()[0]:.2f}")
    times, first = [], None
    for repeat in range(args.repeats):
        started = time.perf_counter()
        results = run_experiment(sweep, args.workers)
        times.append(time.perf_counter() - started)
        ticks = int((results.episodes.steps + 1).sum())
        print(f"  run {repeat + 1}: {times[-1]:.2f} s, {ticks} ticks, "
              f"{ticks / times[-1]:,.0f} swarm ticks/s")
        if first is None:
            first = results.episodes
        elif not np.array_equal(first.row, results.episodes.row):
            print("  results differ between repeats: the simulator is not deterministic")
            return 1
    median = statistics.median(times)
    verdict = "under" if median <= TARGET_SECONDS else "OVER"
    print(f"median {median:.2f} s ({verdict} the {TARGET_SECONDS:.0f} s target)")
    return 0 if median <= TARGET_SECONDS else 1


if __name__ == "__main__":
    sys.exit(main())
