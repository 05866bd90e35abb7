#!/usr/bin/env python3
"""The recording's own CPU time in one process: the seconds the in-process runner's thread spends
in its recorder (``recording.loggers.InProcessRecorder``: the world's and the agents' logging,
and the final flush) over a whole run, per tick, and the size of ``run.rrd``.

Thread CPU time, unlike ``bench/recording_cost.py``'s tick rates, hardly moves with the machine's
other load, so it compares two versions of the logging on a busy machine.

    python -m bench.recording_cpu --agents 8 --grid 11 --episodes 100 --repeats 5
"""

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from bench.harness import add_preset_option, swarm_config
from nnql_swarm.launch.swarm_cli import run_in_process
from nnql_swarm.recording import loggers
from nnql_swarm.world.metrics import read_episodes

SPENT = [0.0]


def timed(method):
    def measured(*args, **kwargs):
        start = time.thread_time()
        try:
            return method(*args, **kwargs)
        finally:
            SPENT[0] += time.thread_time() - start
    return measured


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--grid", type=int, default=11, help="the grid's side")
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--repeats", type=int, default=5)
    add_preset_option(p)
    args = p.parse_args()
    for name in ("on_tick", "on_episode_end", "close"):
        setattr(loggers.InProcessRecorder, name, timed(getattr(loggers.InProcessRecorder, name)))
    config = swarm_config(args.preset, run_id="recording-cpu", n_agents=args.agents,
                          width=args.grid, height=args.grid, episodes=args.episodes)
    seconds, ticks, sizes = [], 0, []
    for _ in range(args.repeats):
        SPENT[0] = 0.0
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            run_in_process(config, out, True, progress=False)
            ticks = int(read_episodes(out / "episodes.csv")[-1]["end_tick"]) + 1
            sizes.append((out / "run.rrd").stat().st_size / 1e6)
        seconds.append(SPENT[0])
    median = statistics.median(seconds)
    print(f"{args.agents} agents on {args.grid}x{args.grid}, {args.episodes} episodes, {ticks} "
          f"ticks: the recorder's CPU {median:.2f} s (median of {args.repeats}: "
          f"{' '.join(f'{s:.2f}' for s in seconds)}), {1e6 * median / ticks:.0f} us a tick; "
          f"run.rrd {statistics.median(sizes):.1f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
