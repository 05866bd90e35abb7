#!/usr/bin/env python3
"""Cost of the wire codec per message, per kind: ``encode`` (it only packs) and ``parse``.

For each message kind, on one valid message as the world and the agents make them (plain ints,
floats and tuples): ``encode`` and ``parse`` of its bytes. Each figure is the median over
``--repeats`` of the mean time of one call, in microseconds, timed with ``timeit`` over enough
calls to take about 0.2 s. With ``--baseline FILE``, another version of ``protocol/messages.py``
(say ``git show main:protocol/messages.py > /tmp/messages_main.py``) is timed alongside on equal
messages, in alternating order, after both are checked to give the same bytes and messages; the
ratio is the median of each repeat's own baseline / current ratio (above 1: the current is faster).

``--updates N`` gives the observation N entries of the shared table's updates, as a
64-agent observation carries some 150 (packed where the codec packs them, protocol 10 on; a
sequence of numbers each before); ``--neighbours K``, K neighbours (packed from protocol 11 on;
an array of ``(id, x, y)`` arrays before).

    python -m bench.codec --repeats 5 --neighbours 4
    python -m bench.codec --repeats 9 --baseline /tmp/messages_main.py
    python -m bench.codec --repeats 9 --neighbours 24 --updates 150 --baseline /tmp/messages_v10.py
"""

import argparse
import importlib.util
import statistics
import sys
import timeit
from pathlib import Path
from types import ModuleType

from nnql_swarm.protocol import messages

RUN = "bench"


def updates(codec: ModuleType, count: int) -> tuple:
    """``count`` entries of the shared table and their values, as ``codec`` carries them."""
    entries, values = range(7, 7 + 13 * count, 13), [25.0 - k / 8 for k in range(count)]
    if not count:
        return ()
    if hasattr(codec, "pack_updates"):
        return codec.pack_updates(entries, values)
    return ((tuple(entries), tuple(values)),)  # protocol 9 and before: numbers


def seen(codec: ModuleType, neighbours) -> object:
    """An observation's neighbours ``(id, x, y)`` as ``codec`` carries them."""
    if hasattr(codec, "pack_neighbours"):
        return codec.pack_neighbours(neighbours)
    return tuple(neighbours)  # protocol 10 and before: arrays


def samples(codec: ModuleType, neighbours: int, entries: int = 0) -> list:
    """One typical message of each kind, for agent 0 (relaying as many intents as it sees)."""
    others = range(1, neighbours + 1)
    return [
        codec.Observation(run=RUN, tick=1234, sender=codec.WORLD_SENDER, agent=0, episode=12,
                          step=34, position=(3, 4), goal=(9, 1),
                          neighbours=seen(codec, [(j, j, 5) for j in others]), rank=2,
                          reward_ds=-0.25,
                          reward_ca=0.0, collided=False, arrived=False, episode_end=False,
                          updates=updates(codec, entries)),
        codec.Answer(run=RUN, tick=1234, sender=codec.agent_sender(0), agent=0, episode=12,
                     action=3, relayed=tuple((j, j % 5) for j in others)),
        codec.Intent(run=RUN, tick=1234, sender=codec.agent_sender(0), agent=0, episode=12,
                     action=3),
        codec.Control(run=RUN, tick=1234, sender=codec.WORLD_SENDER,
                      command=codec.CONTROL_SHUTDOWN),
    ]


def operations(codec: ModuleType, msg) -> dict:
    """Each operation on ``msg`` by ``codec``, checked to round-trip first."""
    kind, payload, key_agent = type(msg), codec.encode(msg), getattr(msg, "agent", None)
    assert codec.parse(payload, kind, RUN, key_agent) == msg
    return {
        "encode": lambda: codec.encode(msg),
        "parse": lambda: codec.parse(payload, kind, RUN, key_agent),
    }


def load(path: Path) -> ModuleType:
    """A messages.py from a file, as a module of its own."""
    spec = importlib.util.spec_from_file_location("baseline_messages", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def per_call_us(fn) -> float:
    timer = timeit.Timer(fn)
    number, _ = timer.autorange()
    return timer.timeit(number) / number * 1e6


def timed(fns: list, repeats: int) -> list[list[float]]:
    """Per repeat, the time of one call of each function, timed in turn (rotating who goes
    first)."""
    rows = []
    for r in range(repeats):
        order = fns[r % len(fns):] + fns[:r % len(fns)]
        times = {fn: per_call_us(fn) for fn in order}
        rows.append([times[fn] for fn in fns])
    return rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--neighbours", type=int, default=4,
                   help="agents in the observation's neighbours and the answer's relayed intents")
    p.add_argument("--updates", type=int, default=0,
                   help="entries of the shared table's updates in the observation")
    p.add_argument("--baseline", type=Path, help="another protocol/messages.py to time alongside")
    args = p.parse_args()
    codecs = [messages] + ([load(args.baseline)] if args.baseline else [])
    print(f"{'kind':>12} {'op':>7} {'µs':>6}" + (f" {'baseline µs':>11} {'ratio':>6}"
                                                  if args.baseline else "") + "  bytes")
    for msgs in zip(*(samples(codec, args.neighbours, args.updates) for codec in codecs)):
        payloads = [codec.encode(msg) for codec, msg in zip(codecs, msgs)]
        same_version = len({codec.PROTOCOL_VERSION for codec in codecs}) == 1
        assert not same_version or len(set(payloads)) == 1, "the baseline gives other bytes"
        ops = [operations(codec, msg) for codec, msg in zip(codecs, msgs)]
        for op in ops[0]:
            rows = timed([o[op] for o in ops], args.repeats)
            current = statistics.median(r[0] for r in rows)
            line = f"{type(msgs[0]).__name__:>12} {op:>7} {current:>6.2f}"
            if args.baseline:
                line += (f" {statistics.median(r[1] for r in rows):>11.2f}"
                         f" {statistics.median(r[1] / r[0] for r in rows):>5.2f}x")
            sizes = "/".join(str(len(p)) for p in dict.fromkeys(payloads))
            print(f"{line}  {sizes}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
