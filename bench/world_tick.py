#!/usr/bin/env python3
"""Microseconds per tick of the swarm's world: one-world rules against the batch rules.

A tick here is the world's own work, ``observations()`` then ``apply(actions)``, with no agents
and no Zenoh: the part of the swarm's lockstep tick between the last agent's intent and the next
observations. For each agent count, in the same run, on the same seeded random actions:

- ``one-world``: :class:`world.engine.SwarmWorld`, on the plain-Python one-world rules;
- ``batch``: ``tests/batch_world.py``'s ``BatchRulesWorld``, the same world on the numpy batch
  rules of ``world.rules`` (a batch of one, as ``SwarmWorld`` was before);
- ``ratio``: batch / one-world, per column.

Each figure is the median over ``--repeats`` of the mean over ``--ticks`` ticks (episode ends
included, as in a run); the two worlds run back to back in every repeat.

    python bench/world_tick.py
    python bench/world_tick.py --agents 8,16,32 --repeats 9 --grid 40x40
"""

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from protocol.actions import N_ACTIONS  # noqa: E402
from protocol.config import SwarmConfig  # noqa: E402
from tests.batch_world import BatchRulesWorld  # noqa: E402
from world.engine import SwarmWorld  # noqa: E402

WORLDS = {"one-world": SwarmWorld, "batch": BatchRulesWorld}


def time_ticks(world: SwarmWorld, actions: list[list[int]]) -> tuple[float, float]:
    """Mean microseconds of ``observations()`` and of ``apply()`` over the given ticks."""
    observing = applying = 0
    clock = time.perf_counter_ns
    for tick_actions in actions:
        start = clock()
        world.observations()
        middle = clock()
        world.apply(tick_actions)
        observing += middle - start
        applying += clock() - middle
    return observing / len(actions) / 1e3, applying / len(actions) / 1e3


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", default="8,32", help="comma-separated agent counts")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--ticks", type=int, default=2000, help="ticks timed per repeat")
    p.add_argument("--grid", default="11x11")
    args = p.parse_args()
    width, height = (int(v) for v in args.grid.split("x"))
    print(f"{'agents':>6} {'world':>9} {'obs us':>7} {'apply us':>8} {'tick us':>8}")
    for n in (int(v) for v in args.agents.split(",")):
        config = SwarmConfig(run_id="bench-run", n_agents=n, width=width, height=height,
                             episodes=10**6)
        actions = np.random.default_rng(0).integers(0, N_ACTIONS, (args.ticks, n)).tolist()
        figures: dict[str, list[tuple[float, float, float]]] = {name: [] for name in WORLDS}
        for _ in range(args.repeats):
            for name, world in WORLDS.items():
                observing, applying = time_ticks(world(config), actions)
                figures[name].append((observing, applying, observing + applying))
        medians = {name: [statistics.median(run[k] for run in runs) for k in range(3)]
                   for name, runs in figures.items()}
        for name, (observing, applying, tick) in medians.items():
            print(f"{n:>6} {name:>9} {observing:>7.1f} {applying:>8.1f} {tick:>8.1f}")
        ratios = [b / o for b, o in zip(medians["batch"], medians["one-world"])]
        print(f"{n:>6} {'ratio':>9}"
              + "".join(f"{r:>{w}.2f}x" for r, w in zip(ratios, (7, 8, 8))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
