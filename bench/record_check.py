#!/usr/bin/env python3
"""Microseconds per tick of the world's check of the learning records (``world.records``).

Runs whole swarms of the default preset (one shared table) in the deterministic simulator of the
distributed swarm (``sim.distributed``: the world's and the agents' own protocol machines, no
faults), the kernel uncompiled as in the world process, and times, per tick of the world, the
record check (``WorldMachine._check_record``, as intents come and as the tick closes, and the
decisions kept for the next tick's records, ``_checked_records``), beside the rest of
the world's tick work in the same runs: applying the tick (``SwarmWorld.apply``, the shared
table's updates included) and building and encoding the next observations. Each figure is the
median over ``--repeats`` runs of the mean over the run's ticks, in CPU time of the thread.

    python -m bench.record_check
    python -m bench.record_check --agents 8,32 --episodes 5 --repeats 5
"""

import argparse
import os
import statistics
import time
from dataclasses import replace

os.environ.setdefault("NNQL_KERNEL", "python")  # as in the world process (unless told)

from bench.harness import agent_sizes
from nnql_swarm.protocol.config import DEFAULT_PRESET, PRESETS, SwarmConfig
from nnql_swarm.sim.distributed import SimSwarm
from nnql_swarm.sim.schedule import DEADLINE_S, Schedule
from nnql_swarm.world.engine import SwarmWorld
from nnql_swarm.world.world_machine import WorldMachine
from nnql_swarm.world.records import RecordCheck

GRIDS = {8: 11, 16: 16, 32: 22, 64: 32}
"""The grid side at each agent count, as ``docs/performance.md`` scales it (constant density)."""


class Timers:
    """Nanoseconds spent in the timed parts of the world, summed over a run."""

    def __init__(self) -> None:
        self.check = self.apply = self.observe = 0
        self.checks = self.ticks = 0

    def install(self) -> None:
        timers, clock = self, time.thread_time_ns  # CPU time: a loaded machine inflates less
        one, closing, apply, encoded = (WorldMachine._check_record,
                                        WorldMachine._checked_records, SwarmWorld.apply,
                                        WorldMachine._encoded)
        self.could_write = could_write = RecordCheck.could_write

        def counted(check, *args):
            timers.checks += 1
            return could_write(check, *args)

        def timed_one(protocol, agent, final):
            start = clock()
            try:
                return one(protocol, agent, final)
            finally:
                timers.check += clock() - start

        def timed_closing(protocol):
            start, nested = clock(), timers.check
            try:
                return closing(protocol)
            finally:
                timers.check += clock() - start - (timers.check - nested)

        def timed_apply(world, *args):
            start = clock()
            try:
                return apply(world, *args)
            finally:
                timers.apply += clock() - start
                timers.ticks += 1

        def timed_encoded(protocol, observations):
            items = encoded(protocol, observations)
            while True:
                start = clock()
                item = next(items, None)
                timers.observe += clock() - start
                if item is None:
                    return
                yield item

        WorldMachine._check_record = timed_one
        RecordCheck.could_write = counted
        WorldMachine._checked_records = timed_closing
        SwarmWorld.apply = timed_apply
        WorldMachine._encoded = timed_encoded


def one_run(agents: int, episodes: int, seed: int, preset: str = DEFAULT_PRESET) -> Timers:
    side = GRIDS.get(agents, 11)
    config = SwarmConfig(**PRESETS[preset], run_id=f"bench{seed}", n_agents=agents,
                         episodes=episodes, max_steps=100, width=side, height=side, seed=seed,
                         tick_deadline_s=DEADLINE_S)
    timers = Timers()
    saved = (WorldMachine._check_record, WorldMachine._checked_records, SwarmWorld.apply,
             WorldMachine._encoded)
    timers.install()
    try:
        outcome = SimSwarm(Schedule(seed, config, (50e-6, 300e-6), ())).run()
    finally:
        (WorldMachine._check_record, WorldMachine._checked_records, SwarmWorld.apply,
         WorldMachine._encoded) = saved
        RecordCheck.could_write = timers.could_write
    assert outcome.failures == [], outcome.failures
    return timers


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=lambda text: agent_sizes(parser, text), default=[8, 32],
                        help="comma-separated agent counts (default: 8,32)")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--preset", choices=tuple(PRESETS), default=DEFAULT_PRESET)
    args = parser.parse_args()
    print("agents  ticks  records/tick  check us/tick  us/record  apply us/tick  observe us/tick")
    for agents in args.agents:
        runs = [one_run(agents, args.episodes, seed, args.preset) for seed in range(args.repeats)]

        def per_tick(part: str) -> float:
            return statistics.median(getattr(r, part) / r.ticks / 1e3 for r in runs)

        per_record = statistics.median(r.check / max(r.checks, 1) / 1e3 for r in runs)
        records = statistics.median(r.checks / r.ticks for r in runs)
        ticks = statistics.median(r.ticks for r in runs)
        print(f"{agents:6d} {ticks:6.0f} {records:13.2f} {per_tick('check'):14.1f} "
              f"{per_record:10.1f} {per_tick('apply'):14.1f} {per_tick('observe'):16.1f}")


if __name__ == "__main__":
    main()
