"""Times the paper's whole Table 1 (k = 1..10, QL and nnQL, 10 seeds, 500 episodes): median of runs.

    python -m bench.table1               # 3 repeats, one thread per core
    python -m bench.table1 --repeats 5 --workers 1

Runs the kernel once untimed (loading or compiling it), then prints each repeat's wall time and
CPU time (a fairer figure when other work shares the cores), the median wall time against the
5 s target, and the table's headline numbers, and checks that every repeat gave the very same
metrics.
"""

import argparse
import os
import resource
import statistics
import sys
import time

import numpy as np

from nnql_swarm.experiment.paper import ALGOS, PaperSettings, RunSpec, run_batch
from nnql_swarm.experiment.report import ResultGrid, summarize, summary_lines, table1_rows

TARGET_SECONDS = 5.0
SEEDS = range(10)
RANDOM_STEPS = range(1, 11)


def cpu_seconds() -> float:
    """User + system CPU time of this process (all its threads)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def specs_of_table1() -> list[RunSpec]:
    return [RunSpec(algo, k, seed) for algo in ALGOS for k in RANDOM_STEPS for seed in SEEDS]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs (default 3)")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="threads the runs are spread over (default: one per core)")
    args = parser.parse_args()
    if args.repeats < 1 or args.workers < 1:
        parser.error("--repeats and --workers must be at least 1")
    run_batch(specs_of_table1()[:2], PaperSettings(episodes=1))  # load or compile the kernel

    settings = PaperSettings()
    specs = specs_of_table1()
    print(f"Table 1: {len(specs)} runs x {settings.episodes} episodes, {args.workers} thread(s), "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f}")
    times, first = [], None
    for repeat in range(args.repeats):
        started, cpu_started = time.perf_counter(), cpu_seconds()
        metrics = run_batch(specs, settings, workers=args.workers)
        times.append(time.perf_counter() - started)
        print(f"  run {repeat + 1}: {times[-1]:.2f} s wall, {cpu_seconds() - cpu_started:.2f} s CPU")
        if first is None:
            first = metrics
        elif not all(np.array_equal(getattr(first, name), getattr(metrics, name))
                     for name in ("steps", "collisions", "reward_ds", "arrived")):
            print("  results differ between repeats: the runner is not deterministic")
            return 1
    median = statistics.median(times)
    verdict = "under" if median < TARGET_SECONDS else "OVER"
    print(f"median {median:.2f} s ({verdict} the {TARGET_SECONDS:.0f} s target)")

    grid = ResultGrid(specs, first)
    print("\n  k      QL    nnQL  decrease %")
    for row in table1_rows(grid):
        print(f"{row['random_step']:3d} {row['ql_collisions']:7.1f} {row['nnql_collisions']:7.1f} "
              f"{row['decrease_pct']:10.2f}")
    for line in summary_lines(summarize(grid, figure_k=max(RANDOM_STEPS))):
        print(f"- {line}")
    return 0 if median < TARGET_SECONDS else 1


if __name__ == "__main__":
    sys.exit(main())
