#!/usr/bin/env python3
"""What the agents' distance fields cost in a distributed swarm's ticks, and how much of the grid
their lazy search covers (``learning.known_map``).

Runs the nodes' real handlers in one thread (``bench/node_cpu.py``'s ``run``, the kernel
uncompiled as in the agent processes) and times every call of ``plan_field`` by the thread's CPU
time. Each time the search runs, it counts the cells it gave a distance and, by a search of the
whole field on a copy of the agent's map, the cells the whole field reaches. Prints the
microseconds a tick the fields took beside the whole tick's handlers, how often a field was
searched, and the share of the reachable cells the lazy search covered.

    python -m bench.distance_field --agents 64 --episodes 6
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NNQL_KERNEL", "python")  # as in the agent processes

from bench.harness import add_preset_option, grid_side, swarm_config
from bench.node_cpu import run
from nnql_swarm.learning import known_map
from nnql_swarm.learning.known_map import MAP_HEADER, grow_field


class FieldMeter:
    """Wraps ``known_map.plan_field`` (as ``known_map.track`` calls it): its CPU time, and at
    each search the cells reached against the whole field's."""

    def __init__(self) -> None:
        self.seconds = 0.0
        self.searches = 0
        self.reached = 0
        self.whole = 0
        self._plan = known_map.plan_field
        self._start = known_map.start_field

    def __enter__(self) -> "FieldMeter":
        known_map.plan_field, known_map.start_field = self._plan_field, self._start_field
        return self

    def __exit__(self, *_) -> None:
        known_map.plan_field, known_map.start_field = self._plan, self._start

    def _start_field(self, *args) -> None:
        self.searches += 1
        self._start(*args)

    def _plan_field(self, wmap, ox, oy, gx, gy, width, height) -> None:
        searches = self.searches
        start = time.thread_time()
        self._plan(wmap, ox, oy, gx, gy, width, height)
        self.seconds += time.thread_time() - start
        if self.searches == searches:
            return
        cells = width * height
        distances = wmap[MAP_HEADER + cells:MAP_HEADER + 2 * cells]
        self.reached += sum(1 for d in distances if d >= 0)
        whole = list(wmap)
        grow_field(whole, -1, width, height)  # the whole field
        self.whole += sum(1 for d in whole[MAP_HEADER + cells:MAP_HEADER + 2 * cells] if d >= 0)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=64)
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--max-steps", type=int, default=100)
    add_preset_option(p)
    args = p.parse_args()
    n = args.agents
    config = swarm_config(args.preset, run_id="fields", n_agents=n, episodes=args.episodes,
                          max_steps=args.max_steps, width=grid_side(n), height=grid_side(n))
    with tempfile.TemporaryDirectory() as tmp, FieldMeter() as meter:
        ticks, wire = run(config, Path(tmp), False, time.thread_time)
    whole_tick = 1e6 * sum(wire.seconds.values()) / ticks
    print(f"{n} agents on {config.width} x {config.height}, preset {args.preset}, {ticks} ticks")
    print(f"  distance fields: {1e6 * meter.seconds / ticks:.0f} us a tick of the handlers' "
          f"{whole_tick:.0f}; {meter.searches} searches")
    if meter.whole:
        print(f"  cells searched: {meter.reached / meter.whole:.2f} of those the whole fields "
              f"reach ({meter.reached} of {meter.whole})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
