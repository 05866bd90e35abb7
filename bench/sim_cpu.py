#!/usr/bin/env python3
"""CPU seconds of the compiled simulator on a fixed batch, on one thread: the kernel's own cost.

Four seeds of one preset, played as one batch by ``sim.runs.Batch`` on a single numba thread,
so that the figure is the kernel's CPU time whatever else the machine runs; the kernel is loaded
(or compiled) by an untimed first episode. Each repeat's CPU time is printed, then the median
and the ticks per CPU second. Two source trees compare through ``PYTHONPATH`` (as
``bench.paired`` builds them), run alternately.

    python -m bench.sim_cpu
    python -m bench.sim_cpu --agents 16 --episodes 600 --repeats 5
"""

import argparse
import statistics
import time

import numba

from bench.harness import add_preset_option, swarm_config
from nnql_swarm.sim.runs import Batch, swarm_world

SEEDS = 4


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=16)
    p.add_argument("--episodes", type=int, default=600)
    p.add_argument("--repeats", type=int, default=5)
    add_preset_option(p)
    args = p.parse_args()
    numba.set_num_threads(1)
    times, ticks = [], 0
    for repeat in range(args.repeats):
        configs = [swarm_config(args.preset, run_id="cpu", n_agents=args.agents,
                                episodes=args.episodes + 1, max_steps=100,
                                width=max(11, 2 * args.agents // 11 + 1), height=11, seed=s)
                   for s in range(SEEDS)]
        batch = Batch(swarm_world(configs[0]), configs)
        batch.play(1)
        started = time.process_time()
        episodes = batch.play(args.episodes)
        times.append(time.process_time() - started)
        ticks = int(episodes.steps.sum() + episodes.steps.size)
        print(f"  repeat {repeat + 1}: {times[-1]:.2f} s of CPU", flush=True)
    median = statistics.median(times)
    print(f"{args.preset}, {args.agents} agents x {SEEDS} seeds x {args.episodes} episodes "
          f"({ticks} ticks): median {median:.2f} s of CPU ({min(times):.2f} to "
          f"{max(times):.2f}), {ticks / median:,.0f} ticks a CPU second")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
