#!/usr/bin/env python3
"""How fast a lockstep chain of Zenoh processes can go, by message pattern: no rules, no learning.

A world process and N agent processes (spawn; embedded peers on loopback, multicast off), as in
the swarm. Each tick the world sends every agent its rank (one message each, first rank first);
each agent waits for the intents of all agents ranked above it, then announces STAY at once; the
world waits for the tick's intents. Patterns for how an intent reaches the agents ranked below:

- ``pubsub``:   every agent publishes its intent, every agent subscribes to all intents;
- ``query``:    each agent asks the agent ranked just above it with a ``get`` sent one tick
                ahead and held until that agent decides; answers relay every intent known;
- ``standing``: the same, with one standing query per agent, answered at every tick;
- ``token``:    each agent hands the intents so far to the next; the last one to the world.

Except in ``token``, the world gets every intent by subscription. Messages are bare msgpack
tuples. This is what ``docs/performance.md`` quotes; the swarm itself
uses ``standing`` (``agent.negotiation``), with its codec, rules and learning on top.

    python -m bench.zenoh_patterns --agents 8 --repeats 3
"""

import argparse
import multiprocessing as mp
import queue
import statistics
import sys
import time

import msgpack
import zenoh


from nnql_swarm.transport.callbacks import enqueue
from nnql_swarm.transport.ports import free_port
from nnql_swarm.transport.settings import TransportSettings, open_session

PATTERNS = ("pubsub", "query", "standing", "token")
NONE = zenoh.ConsolidationMode.NONE
STAY = 4


def session(endpoint: str, world: bool) -> zenoh.Session:
    settings = (TransportSettings(listen=(endpoint,)) if world else
                TransportSettings(listen=("tcp/127.0.0.1:0",), connect=(endpoint,)))
    return open_session(settings)  # as the swarm's processes: one receiving thread


def to_queue(events: queue.SimpleQueue, kind: str):
    return enqueue(events, kind)  # as the swarm's handlers: Zenoh's thread keeps its state


def agent(me: int, n: int, endpoint: str, pattern: str) -> None:
    """One agent: announce STAY at every tick once the intents ranked above are known."""
    above = (me - 1) % n
    events: queue.SimpleQueue = queue.SimpleQueue()
    with session(endpoint, world=False) as s:
        s.declare_subscriber(f"w/obs/{me}", to_queue(events, "obs"))
        s.declare_subscriber(f"a/{me}/token", to_queue(events, "token"))
        s.declare_queryable(f"a/{me}/intent", to_queue(events, "query"))
        if pattern == "pubsub":
            s.declare_subscriber("a/*/intent", to_queue(events, "intent"))
        intent_pub = s.declare_publisher(f"a/{me}/intent", express=True)
        token_pubs = [s.declare_publisher(f"a/{j}/token", express=True) for j in range(n)]
        world_pub = s.declare_publisher("w/intents", express=True)
        s.liveliness().declare_token(f"alive/{me}")
        time.sleep(1.0)  # let the mesh form before asking anyone
        if pattern == "standing":
            s.get(f"a/{above}/intent?standing", to_queue(events, "answer"), consolidation=NONE,
                  timeout=600)
        known: dict[int, dict[int, int]] = {}  # tick -> agent -> action
        held: dict[int, list] = {}
        standing: list = []
        later: list = []
        decided = -1

        def answer(query, tick: int) -> None:
            query.reply(query.key_expr, msgpack.packb((tick, list(known[tick].items()))))

        def handle(kind: str, item) -> None:
            if kind in ("intent", "token") or (kind == "answer" and item.ok is not None):
                payload = item.payload if kind != "answer" else item.ok.payload
                t, actions = msgpack.unpackb(payload.to_bytes())
                if t > decided:
                    known.setdefault(t, {}).update(dict(actions))
            elif kind == "query":
                asked = str(item.parameters)
                if asked == "standing":
                    standing.append(item)
                elif int(asked) <= decided:
                    answer(item, int(asked))
                    item.drop()
                else:
                    held.setdefault(int(asked), []).append(item)
            elif kind == "obs":
                later.append(item)

        while True:
            item = later.pop(0) if later else None
            if item is None:
                kind, item = events.get()
                if kind != "obs":
                    handle(kind, item)
                    continue
            tick, rank = msgpack.unpackb(item.payload.to_bytes())
            if tick < 0:
                return
            need = [j for j in range(n) if (j - tick) % n < rank]
            if pattern == "query" and need and tick not in known:
                s.get(f"a/{above}/intent?{tick}", to_queue(events, "answer"),
                      consolidation=NONE, timeout=1.0)
            while not all(j in known.get(tick, {}) for j in need):
                handle(*events.get())
            known.setdefault(tick, {})[me] = STAY
            decided = tick
            for query in standing:
                answer(query, tick)
            for query in held.pop(tick, []):
                answer(query, tick)
                query.drop()
            everything = msgpack.packb((tick, list(known[tick].items())))
            if pattern != "token":
                intent_pub.put(msgpack.packb((tick, [(me, STAY)])))
            elif rank == n - 1:
                world_pub.put(everything)
            else:
                token_pubs[(me + 1) % n].put(everything)
            if pattern == "query" and (me - tick - 1) % n > 0:
                s.get(f"a/{above}/intent?{tick + 1}", to_queue(events, "answer"),
                      consolidation=NONE, timeout=1.0)
            known = {t: v for t, v in known.items() if t >= tick}


def world(n: int, endpoint: str, pattern: str, ticks: int, results) -> None:
    """The clock: send each agent its rank, wait for the tick's intents; report ticks/s."""
    events: queue.SimpleQueue = queue.SimpleQueue()
    alive: set[str] = set()
    with session(endpoint, world=True) as s:
        key = "w/intents" if pattern == "token" else "a/*/intent"
        s.declare_subscriber(key, to_queue(events, "intent"))
        s.liveliness().declare_subscriber(
            "alive/*", zenoh.handlers.Callback(lambda t: alive.add(str(t.key_expr))), history=True)
        pubs = [s.declare_publisher(f"w/obs/{i}", express=True) for i in range(n)]
        while len(alive) < n:
            time.sleep(0.05)
        time.sleep(2.0)
        warm_up, start = ticks // 5, 0.0
        for tick in range(ticks):
            if tick == warm_up:
                start = time.perf_counter()
            for rank in range(n):
                pubs[(tick + rank) % n].put(msgpack.packb((tick, rank)))
            heard: set[int] = set()
            while len(heard) < n:
                _, sample = events.get()
                t, actions = msgpack.unpackb(sample.payload.to_bytes())
                if t == tick:
                    heard.update(j for j, _ in actions)
        results.put((ticks - warm_up) / (time.perf_counter() - start))
        for pub in pubs:
            pub.put(msgpack.packb((-1, 0)))
        time.sleep(0.5)


def run(pattern: str, n: int, ticks: int) -> float:
    ctx = mp.get_context("spawn")
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    results = ctx.Queue()
    processes = [ctx.Process(target=world, args=(n, endpoint, pattern, ticks, results))]
    processes += [ctx.Process(target=agent, args=(i, n, endpoint, pattern)) for i in range(n)]
    for p in processes:
        p.start()
        time.sleep(0.05)
    try:
        rate = results.get(timeout=120)
    except queue.Empty:
        rate = float("nan")  # a run that never finished: reported, not fatal
    for p in processes:
        p.join(5)
        if p.is_alive():
            p.kill()
    return rate


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--ticks", type=int, default=1500)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--patterns", default=",".join(PATTERNS))
    args = p.parse_args()
    for pattern in args.patterns.split(","):
        if pattern not in PATTERNS:
            print(f"unknown pattern {pattern!r}; choose from {', '.join(PATTERNS)}")
            return 2
        rates = [run(pattern, args.agents, args.ticks) for _ in range(args.repeats)]
        print(f"{pattern:>9} {statistics.median(rates):7.0f} ticks/s  "  # nan: a run hung
              f"({' '.join(f'{r:.0f}' for r in rates)})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
