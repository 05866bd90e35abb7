"""Times the paper's whole Table 1 (k = 1..10, QL and nnQL, 10 seeds, 500 episodes): median of runs.

    python bench/table1.py               # 3 repeats, in this one process
    python bench/table1.py --repeats 5 --workers 2

Prints each repeat's wall time and CPU time (this process and its workers: a fairer figure when
other work shares the cores), the median wall time against the 60 s target (DESIGN §6), and the
table's headline numbers, and checks that every repeat gave the very same metrics.
"""

import argparse
import os
import resource
import statistics
import sys
import time
from pathlib import Path

if __package__ in (None, ""):  # run as a script: make the repository's packages importable
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from launch.paper import ALGOS, PaperSettings, RunSpec, run_batch  # noqa: E402
from launch.report import ResultGrid, summarize, summary_lines, table1_rows  # noqa: E402

TARGET_SECONDS = 60.0
SEEDS = range(10)
RANDOM_STEPS = range(1, 11)


def cpu_seconds() -> float:
    """User + system CPU time of this process and of its finished worker processes."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="timed runs (default 3)")
    parser.add_argument("--workers", type=int, default=1,
                        help="worker processes (default 1: at this size a second one costs more "
                        "than it saves)")
    args = parser.parse_args()
    if args.repeats < 1 or args.workers < 1:
        parser.error("--repeats and --workers must be at least 1")

    settings = PaperSettings()
    specs = [RunSpec(algo, k, seed) for algo in ALGOS for k in RANDOM_STEPS for seed in SEEDS]
    print(f"Table 1: {len(specs)} runs x {settings.episodes} episodes, {args.workers} worker(s), "
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
