#!/usr/bin/env python3
"""Where a tick's time goes: the distributed swarm, with every process marking each step it takes.

Runs the launcher's world and agent processes (embedded Zenoh, recording off) with ``NNQL_TRACE``
set (``protocol.trace``), then lines up the marks of every tick after the first episode: from the
world's first observation through each agent's decision and each answer (from the agent that
sent it to the one that got it) to the world closing the tick after the last intent. Medians and
90th percentiles in microseconds. With the paper's preset (``--preset nnql``, radius 10) the
negotiation is one chain of every agent; with the default (radius 2) the waits are only among
agents in reach: fewer answers a tick, several short chains side by side (docs/performance.md).
Then the whole ticks by where they fall in their episode: an episode's end tick (every agent
observes it and checkpoints before its intent), the first tick of the next (everyone placed
anew), the others, with each one's share of the time measured.

    python -m bench.tick_trace --agents 8 --episodes 15
    python -m bench.tick_trace --agents 64 --episodes 8
"""

import argparse
import json
import os
import statistics
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

from bench.harness import (
    add_preset_option, grid_side, measured_rate, run_distributed, swarm_config,
)
from nnql_swarm.protocol import trace
from nnql_swarm.world.metrics import read_episodes

FIRST_OBS = "world: first observation handed to Zenoh -> its agent has it"
FIRST_DECIDES = "that agent: observation in -> deciding"
LEARNING = "each agent: deciding -> action chosen (the learning)"
ENCODING = "each agent: action chosen -> answer encoded"
REPLYING = "each agent that sends an intent: answer encoded -> the agents below answered"
HOP = "each answer: encoded by its sender -> its asker has it"
ANSWER_IN = "each agent that waited: its last answer in -> deciding"
INTENT = "each agent that sends an intent: answered -> intent handed to Zenoh"
LAST_INTENT = "the tick's last intent handed over -> the world closes the tick"
NEXT_OBS = "the world: closing -> next tick's first observation handed over"
TICK = "a whole tick"
STEPS = (FIRST_OBS, FIRST_DECIDES, LEARNING, ENCODING, REPLYING, HOP, ANSWER_IN, INTENT,
         LAST_INTENT, NEXT_OBS, TICK)
AGENT_MARKS = (trace.OBS_IN, trace.DECIDE, trace.ACTED, trace.ENCODED)
SENDING_MARKS = (trace.ANSWERED, trace.INTENT_SENT)
"""Marked only by the agents that send the world an intent (a settled agent sends none)."""


def sends(marks: dict) -> bool:
    """Whether an agent's marks of a tick show it sent the world an intent."""
    return all(step in marks for step in SENDING_MARKS)


def by_tick(marks: list) -> dict[int, dict]:
    """One process's marks as tick -> step -> the first time it was marked; the answers in
    (marked with their senders) as tick -> ``ANSWER_IN`` -> sender -> the time it came."""
    ticks: dict[int, dict] = defaultdict(dict)
    for step, tick, at, *peer in marks:
        if peer:
            ticks[tick].setdefault(step, {}).setdefault(peer[0], at)
        else:
            ticks[tick].setdefault(step, at)
    return ticks


def tick_steps(world: dict[int, dict], agents: dict[int, dict[int, dict]],
               ticks: list[int]) -> dict[str, list[float]]:
    """Each step of :data:`STEPS` for every tick in ``ticks`` that has all its marks, in seconds."""
    n = len(agents)
    out: dict[str, list[float]] = {step: [] for step in STEPS}
    for tick in ticks:
        w, after = world.get(tick, {}), world.get(tick + 1, {})
        chain = [a for a in (agents[(rank + tick) % n].get(tick, {}) for rank in range(n))
                 if trace.OBS_IN in a]  # by rank, the agents sent an observation (not quiet ones)
        senders = [a for a in chain if sends(a)]
        if (trace.OBS_SENT not in w or trace.CLOSE not in w or trace.OBS_SENT not in after
                or not senders or not all(step in a for a in chain for step in AGENT_MARKS)
                or not all(trace.ENCODED in agents.get(s, {}).get(tick, {})
                           for a in chain for s in a.get(trace.ANSWER_IN, ()))):
            continue
        first = chain[0]
        out[FIRST_OBS].append(first[trace.OBS_IN] - w[trace.OBS_SENT])
        out[FIRST_DECIDES].append(first[trace.DECIDE] - first[trace.OBS_IN])
        for a in chain:
            out[LEARNING].append(a[trace.ACTED] - a[trace.DECIDE])
            out[ENCODING].append(a[trace.ENCODED] - a[trace.ACTED])
            if sends(a):
                out[REPLYING].append(a[trace.ANSWERED] - a[trace.ENCODED])
                out[INTENT].append(a[trace.INTENT_SENT] - a[trace.ANSWERED])
            came = a.get(trace.ANSWER_IN, {})
            out[HOP].extend(at - agents[sender][tick][trace.ENCODED]
                            for sender, at in came.items())
            if came:
                out[ANSWER_IN].append(a[trace.DECIDE] - max(came.values()))
        out[LAST_INTENT].append(w[trace.CLOSE] - max(a[trace.INTENT_SENT] for a in senders))
        out[NEXT_OBS].append(after[trace.OBS_SENT] - w[trace.CLOSE])
        out[TICK].append(after[trace.OBS_SENT] - w[trace.OBS_SENT])
    return out


PLACES = ("an episode's end tick", "the first tick of the next", "every other tick")


def ticks_by_place(world: dict[int, dict], ends: set[int], ticks: list[int]) -> dict:
    """Each whole tick of ``ticks`` (the world's first observation of it to the next one's), in
    seconds, by where it falls: the end tick of an episode (``ends``), the first tick of the
    next, the others."""
    out: dict[str, list[float]] = {place: [] for place in PLACES}
    for tick in ticks:
        w, after = world.get(tick, {}), world.get(tick + 1, {})
        if trace.OBS_SENT in w and trace.OBS_SENT in after:
            place = PLACES[0] if tick in ends else PLACES[1] if tick - 1 in ends else PLACES[2]
            out[place].append(after[trace.OBS_SENT] - w[trace.OBS_SENT])
    return out


def read_trace(directory: Path, n_agents: int) -> tuple[dict, dict]:
    """The world's and every agent's marks, by tick, from ``directory``."""
    def load(name: str):
        return by_tick(json.loads((directory / f"{name}.json").read_text()))
    return load("world"), {i: load(f"agent-{i}") for i in range(n_agents)}


def percentile(values: list[float], q: float) -> float:
    return sorted(values)[min(int(len(values) * q), len(values) - 1)]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=15)
    p.add_argument("--max-steps", type=int, default=100)
    add_preset_option(p)
    args = p.parse_args()
    if args.agents < 2 or args.episodes < 2:
        p.error("need at least 2 agents and 2 episodes (the first one is warm-up)")
    side = grid_side(args.agents)  # about 16 cells an agent, as bench.scale
    config = swarm_config(args.preset, run_id="trace", n_agents=args.agents,
                          episodes=args.episodes, max_steps=args.max_steps, width=side,
                          height=side)
    with tempfile.TemporaryDirectory() as tmp:
        marks, out = Path(tmp) / "marks", Path(tmp) / "run"
        os.environ[trace.TRACE_ENV] = str(marks)  # the spawned processes inherit it
        run_distributed(config, out, record=False)
        world, agents = read_trace(marks, args.agents)
        ends = [int(row["end_tick"]) for row in read_episodes(out / "episodes.csv")]
        timed = [t for t in sorted(world) if t > ends[0]]
        steps = tick_steps(world, agents, timed)
        places = ticks_by_place(world, set(ends), timed)
        rate = measured_rate(out)
    print(f"{args.agents} agents, {rate:.0f} ticks/s after the first episode; microseconds:")
    print(f"{'step':<66} {'median':>7} {'p90':>7} {'n':>6}")
    for step, values in steps.items():
        if values:
            print(f"{step:<66} {1e6 * statistics.median(values):>7.0f} "
                  f"{1e6 * percentile(values, 0.9):>7.0f} {len(values):>6}")
    total = sum(map(sum, places.values()))
    print(f"\n{'whole ticks, by where they fall':<40} {'median':>7} {'p90':>7} {'n':>6} "
          f"{'share of the time':>18}")
    for place, values in places.items():
        if values:
            print(f"{place:<40} {1e6 * statistics.median(values):>7.0f} "
                  f"{1e6 * percentile(values, 0.9):>7.0f} {len(values):>6} "
                  f"{sum(values) / total:>18.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
