#!/usr/bin/env python3
"""Microseconds per tick of the swarm's world, as the world process runs it (kernel uncompiled).

A tick here is the world's own work, ``observations()`` then ``apply(actions)``, with no agents
and no Zenoh: the part of the swarm's lockstep tick between the last agent's intent and the next
observations, on seeded random actions (under ``--arbitration pibt``, ``--preset pibt-nnql``,
each agent's order a seeded random one of its moves, the action first). Each figure is the median
over ``--repeats`` of the mean over ``--ticks`` ticks (episode ends included, as in a run).

    python -m bench.world_tick
    python -m bench.world_tick --agents 8,16,32 --repeats 9 --grid 40x40
    python -m bench.world_tick --agents 8,64 --grid 32x32 --preset pibt-nnql
"""

import argparse
import os
import statistics
import sys
import time

os.environ["NNQL_KERNEL"] = "python"  # as in the world process

import numpy as np

from bench.harness import agent_sizes, grid_side, swarm_config
from nnql_swarm.launch.cli import parse_grid
from nnql_swarm.protocol.actions import N_ACTIONS
from nnql_swarm.protocol.config import DEFAULT_PRESET, PRESETS
from nnql_swarm.world.engine import SwarmWorld


def time_ticks(world: SwarmWorld, orders: list[list[tuple[int, ...]]]) -> tuple[float, float]:
    """Mean microseconds of ``observations()`` and of ``apply()`` over the given ticks: each
    agent's action the first of its order (the orders are read only under priority
    inheritance)."""
    observing = applying = 0
    clock = time.perf_counter_ns
    for tick_orders in orders:
        actions = [order[0] for order in tick_orders]
        start = clock()
        world.observations()
        middle = clock()
        world.apply(actions, None, tick_orders)
        observing += middle - start
        applying += clock() - middle
    return observing / len(orders) / 1e3, applying / len(orders) / 1e3


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=lambda text: agent_sizes(p, text), default=[8, 32],
                   help="comma-separated agent counts (default: 8,32)")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--ticks", type=int, default=2000, help="ticks timed per repeat")
    p.add_argument("--grid", type=parse_grid,
                   help="WIDTHxHEIGHT (default: the scale benchmark's grid for each agent count, "
                        "11x11 for 8)")
    p.add_argument("--preset", choices=tuple(PRESETS), default=DEFAULT_PRESET,
                   help="learning options (pibt-nnql: the world arbitrates by priority "
                        "inheritance)")
    args = p.parse_args()
    grids = [args.grid or (grid_side(n), grid_side(n)) for n in args.agents]
    configs = [swarm_config(args.preset, run_id="bench-run", n_agents=n, width=width,
                            height=height, episodes=10**6)
               for n, (width, height) in zip(args.agents, grids)]
    print(f"{'agents':>6} {'obs us':>7} {'apply us':>8} {'tick us':>8}")
    for config in configs:
        n = config.n_agents
        rng = np.random.default_rng(0)
        orders = [[tuple(rng.permutation(N_ACTIONS).tolist()) for _ in range(n)]
                  for _ in range(args.ticks)]
        runs = []
        for _ in range(args.repeats):
            observing, applying = time_ticks(SwarmWorld(config), orders)
            runs.append((observing, applying, observing + applying))
        observing, applying, tick = (statistics.median(run[k] for run in runs) for k in range(3))
        print(f"{n:>6} {observing:>7.1f} {applying:>8.1f} {tick:>8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
