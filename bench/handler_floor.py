#!/usr/bin/env python3
"""The floor of a Python handler: what the least a swarm process does with a message costs, warm
and on cooled caches.

The observations of a real run (``bench.node_cpu``'s harness: the default preset, 8 agents on
11 x 11, the first ``--episodes`` episodes) are handed, one call each, to handlers that do ever
less than the agent's: the codec's checked parse of the observation with an intent built and
encoded for it (the least an agent sends back), the checked parse alone, msgspec's decoding
alone, and a function that does nothing. Each call is timed by the thread's CPU time, warm (the
calls one after the other) and cooled (``bench.node_cpu.CacheEvictor`` before each, as a swarm
process wakes); medians over the calls. Set against the budget half the bare loop leaves our
Python a tick (docs/performance.md, "Where the gap is"), it says how much of that budget the
codec alone takes, whatever the rest of a handler is written in.

    python -m bench.handler_floor --episodes 3
"""

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NNQL_KERNEL", "python")  # as in the swarm's processes

import msgspec

from bench import node_cpu
from bench.harness import grid_side, swarm_config
from nnql_swarm.protocol.config import DEFAULT_PRESET
from nnql_swarm.protocol.messages import Intent, Observation, agent_sender, encode, parse

RUN_ID = "floor"


def observations(agents: int, episodes: int) -> list[bytes]:
    """The payloads of every observation the world sends in a run of the default preset."""
    side = grid_side(agents)
    config = swarm_config(DEFAULT_PRESET, run_id=RUN_ID, n_agents=agents, episodes=episodes,
                          max_steps=100, width=side, height=side)
    payloads: list[bytes] = []

    def on_send(number, kind, sender, receiver, item, cause) -> None:
        if kind == "observation":
            payloads.append(item.payload)

    with tempfile.TemporaryDirectory() as tmp:
        node_cpu.run(config, Path(tmp), False, on_send=on_send)
    return payloads


_RAW = msgspec.msgpack.Decoder()


def nothing(payload: bytes) -> None:
    return None


def decode_only(payload: bytes) -> None:
    _RAW.decode(payload)


def parse_only(payload: bytes) -> None:
    parse(payload, Observation, RUN_ID)


def parse_and_answer(payload: bytes) -> None:
    obs = parse(payload, Observation, RUN_ID)
    encode(Intent(RUN_ID, obs.tick, agent_sender(obs.agent), obs.agent, obs.episode, 0, (), (),
                  obs.world))


HANDLERS = {
    "an empty function": nothing,
    "msgspec's decoding": decode_only,
    "the checked parse": parse_only,
    "the parse, an intent encoded": parse_and_answer,
}


def time_calls(handler, payloads: list[bytes], before_each=None) -> float:
    """The median microseconds of CPU of one call of ``handler`` over ``payloads``."""
    spent = []
    for payload in payloads:
        if before_each is not None:
            before_each()
        start = time.thread_time_ns()
        handler(payload)
        spent.append(time.thread_time_ns() - start)
    return statistics.median(spent) / 1000


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=3)
    p.add_argument("--calls", type=int, default=400, help="observations timed (at most)")
    args = p.parse_args()
    payloads = observations(args.agents, args.episodes)[:args.calls]
    cool = node_cpu.CacheEvictor()
    print(f"{len(payloads)} observations of {args.agents} agents; us of CPU a call, median")
    print(f"  {'handler':<30} {'warm':>6} {'cooled':>7}")
    for name, handler in HANDLERS.items():
        print(f"  {name:<30} {time_calls(handler, payloads):6.1f} "
              f"{time_calls(handler, payloads, cool):7.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
