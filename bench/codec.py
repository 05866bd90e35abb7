#!/usr/bin/env python3
"""Cost of the wire codec per message: the compiled fast path against the generic reference path.

For each message kind, on one valid message as the world and the agents make them (plain ints,
floats and tuples), in the same run: ``encode`` (which validates, then packs) against the generic
``to_wire`` packed alike, and ``parse`` of bytes against the generic parse (which ``parse`` falls
back on when in doubt). Both sides are checked to give the same bytes and the same message first.
Each figure is the median over ``--repeats`` of the mean time of one call, in microseconds,
timed with ``timeit`` over enough calls to take about 0.2 s; the ratio is the median of each
repeat's own reference / fast ratio (the two are timed back to back, in alternating order).

    python bench/codec.py --repeats 5 --neighbours 4
"""

import argparse
import statistics
import sys
import timeit
from pathlib import Path

import msgpack

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from protocol import messages  # noqa: E402
from protocol.messages import (  # noqa: E402
    CONTROL_SHUTDOWN, WORLD_SENDER, Answer, Control, Intent, Observation, agent_sender, encode,
    parse,
)

RUN = "bench"


def samples(neighbours: int) -> list:
    """One typical message of each kind, for agent 0 (relaying as many intents as it sees)."""
    others = range(1, neighbours + 1)
    return [
        Observation(run=RUN, tick=1234, sender=WORLD_SENDER, agent=0, episode=12, step=34,
                    position=(3, 4), goal=(9, 1), neighbours=tuple((j, j, 5) for j in others),
                    rank=2, reward_ds=-0.25, reward_ca=0.0, collided=False, arrived=False,
                    episode_end=False),
        Answer(run=RUN, tick=1234, sender=agent_sender(0), agent=0, episode=12, action=3,
               relayed=tuple((j, j % 5) for j in others)),
        Intent(run=RUN, tick=1234, sender=agent_sender(0), agent=0, episode=12, action=3),
        Control(run=RUN, tick=1234, sender=WORLD_SENDER, command=CONTROL_SHUTDOWN),
    ]


def generic_encode(msg) -> bytes:
    return msgpack.packb(messages._generic_to_wire(msg), use_bin_type=True)


def operations(msg) -> dict:
    """Each operation on ``msg`` as (generic, fast), checked to give the same result."""
    kind, payload, key_agent = type(msg), encode(msg), getattr(msg, "agent", None)
    assert payload == generic_encode(msg)
    assert parse(payload, kind, RUN, key_agent) == messages._generic_parse(
        payload, kind, RUN, key_agent) == msg
    return {
        "encode": (lambda: generic_encode(msg), lambda: encode(msg)),
        "parse": (lambda: messages._generic_parse(payload, kind, RUN, key_agent),
                  lambda: parse(payload, kind, RUN, key_agent)),
    }


def per_call_us(fn) -> float:
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    return timer.timeit(number) / number * 1e6


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--neighbours", type=int, default=4,
                   help="agents in the observation's neighbours and the answer's relayed intents")
    args = p.parse_args()
    print(f"{'kind':>12} {'op':>7} {'generic µs':>10} {'fast µs':>8} {'ratio':>6}  bytes")
    for msg in samples(args.neighbours):
        for op, (generic, fast) in operations(msg).items():
            times = []
            for r in range(args.repeats):
                order = (generic, fast) if r % 2 == 0 else (fast, generic)
                timed = {fn: per_call_us(fn) for fn in order}
                times.append((timed[generic], timed[fast]))
            slow = statistics.median(g for g, _ in times)
            quick = statistics.median(f for _, f in times)
            ratio = statistics.median(g / f for g, f in times)
            print(f"{type(msg).__name__:>12} {op:>7} {slow:>10.2f} {quick:>8.2f} {ratio:>5.1f}x  "
                  f"{len(encode(msg))}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
