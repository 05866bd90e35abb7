#!/usr/bin/env python3
"""The bare Zenoh lockstep loop: what a tick costs when every agent answers at once.

A world process and N agent processes (spawn; one machine, the launcher's Zenoh settings and
layout, multicast off). Each tick the world publishes every agent its observation (a small
msgpack tuple, first rank first); each agent answers with its intent the moment its observation
arrives, from Zenoh's callback; the world waits for every intent, then opens the next tick from
its own callback. No negotiation, no codec, no rules, no learning: the floor under the swarm's
tick, for the same number of processes and the same topology. Beside its ticks a second, the
machine's busy CPU microseconds a tick (``CPU us``: every process's, Zenoh's threads and the
kernel's, from ``/proc/stat``). With ``--python-work`` each agent first reads as many small
Python objects (:func:`python_work`): a loop with as much Python as the swarm's, and none of its
protocol; ``work us`` is what that costs a tick hot in one thread, every agent's together (as
``bench.node_cpu`` times the swarm's handlers).

    python -m bench.lockstep --agents 8,32,64 --repeats 3 --topology mesh
    python -m bench.lockstep --agents 8 --repeats 3 --python-work 0,100,200,300,400
"""

import argparse
import statistics
import sys
import threading
import time
import timeit
from typing import Callable

import msgpack

from bench.harness import agent_sizes
from bench.procstat import MemorySampler, TimedTicks
from nnql_swarm.launch.processes import process_context
from nnql_swarm.transport.callbacks import callback
from nnql_swarm.transport.ports import wait_listening
from nnql_swarm.transport.runtime import declare_lockstep_publisher
from nnql_swarm.transport.settings import TransportSettings, open_session
from nnql_swarm.transport.topology import TOPOLOGIES, EmbeddedLayout

START_TIMEOUT_S = 120.0


def warm_up_ticks(ticks: int) -> int:
    """How many of a loop's first ticks are not timed."""
    return ticks // 5


def python_work(objects: int) -> Callable[[], int]:
    """A stand-in for a handler's Python: each call reads ``objects`` small dicts, scattered
    over four times as many (what a call costs hot: :func:`hot_us`)."""
    store = [{"a": i, "b": [i, i + 1]} for i in range(4 * objects)]

    def work() -> int:
        total = 0
        for k in range(0, len(store), 4):
            item = store[k]
            total += item["a"] + item["b"][1]
        return total

    return work


def agent(me: int, transport: TransportSettings, work_objects: int = 0) -> None:
    """Answer every observation with an intent, after :func:`python_work` over
    ``work_objects`` objects if any; leave on a negative tick."""
    done = threading.Event()
    work = python_work(work_objects) if work_objects else None
    with open_session(transport) as s:
        publisher = declare_lockstep_publisher(s, f"bare/intent/{me}")

        def on_obs(sample) -> None:
            tick, _rank = msgpack.unpackb(sample.payload.to_bytes())
            if tick < 0:
                done.set()
                return
            if work is not None:
                work()
            publisher.put(msgpack.packb((tick, me, 4)))

        s.declare_subscriber(f"bare/obs/{me}", callback(on_obs))
        token = s.liveliness().declare_token(f"bare/alive/{me}")  # alive while referenced
        done.wait()
        token.undeclare()
        time.sleep(0.2)


def world(n: int, transport: TransportSettings, ticks: int, results) -> None:
    """The clock; puts ``(ticks a second, the time every agent was alive, the machine's busy
    CPU microseconds a tick, when the timed ticks ran)`` on ``results`` (rate, CPU and window:
    the ticks after the warm-up; the window in seconds since the epoch)."""
    alive: set[str] = set()
    everyone = threading.Event()
    finished = threading.Event()
    state = {"tick": 0, "heard": 0}
    timed = TimedTicks()
    warm_up = warm_up_ticks(ticks)
    with open_session(transport) as s:
        pubs = [declare_lockstep_publisher(s, f"bare/obs/{i}") for i in range(n)]

        def open_tick(tick: int) -> None:
            for rank in range(n):
                pubs[(tick + rank) % n].put(msgpack.packb((tick, rank)))

        def on_intent(sample) -> None:
            tick, _agent, _action = msgpack.unpackb(sample.payload.to_bytes())
            if tick != state["tick"]:
                return
            state["heard"] += 1
            if state["heard"] < n:
                return
            state["tick"], state["heard"] = tick + 1, 0
            if tick + 1 == warm_up:
                timed.start()
            if tick + 1 == ticks:
                finished.set()
            else:
                open_tick(tick + 1)

        def on_alive(sample) -> None:
            alive.add(str(sample.key_expr))
            if len(alive) == n:
                everyone.set()

        s.declare_subscriber("bare/intent/*", callback(on_intent))
        s.liveliness().declare_subscriber("bare/alive/*", callback(on_alive), history=True)
        if not everyone.wait(START_TIMEOUT_S):
            print(f"world: only {len(alive)} of {n} agents alive", file=sys.stderr, flush=True)
            results.put((float("nan"), float("nan"), float("nan"), timed.window))
            return
        startup = time.time()
        time.sleep(0.5)  # let late declarations settle before the clock starts
        open_tick(0)
        if not finished.wait(START_TIMEOUT_S):
            results.put((float("nan"), startup, float("nan"), timed.window))
        else:
            rate, cpu_us = timed.measure(ticks - warm_up)
            results.put((rate, startup, cpu_us, timed.window))
        for pub in pubs:
            pub.put(msgpack.packb((-1, 0)))
        time.sleep(0.3)


def router(transport: TransportSettings) -> None:
    """A bare Zenoh router, until killed."""
    with open_session(transport):
        threading.Event().wait()


def run(n: int, topology: str, ticks: int, work_objects: int = 0) -> dict:
    """One bare loop of ``n`` agents (each handler of an agent doing :func:`python_work` over
    ``work_objects`` objects first, if any): ``rate`` (ticks a second), ``startup_s`` (until every
    agent was alive), ``cpu_us`` (the machine's busy CPU microseconds a tick), ``rss`` (peak MiB
    by process name), and the ticks ``rate`` and ``cpu_us`` count: ``measured_ticks``, and
    ``window``, when they ran (seconds since the epoch)."""
    ctx = process_context()  # started as the swarm's processes are
    layout = EmbeddedLayout(topology=topology)
    results = ctx.Queue()
    extra = []
    if layout.router() is not None:
        extra.append(("router", ctx.Process(target=router, args=(layout.router(),))))
    processes = extra + [("world", ctx.Process(target=world,
                                               args=(n, layout.world(), ticks, results)))]
    processes += [(f"agent-{i}", ctx.Process(target=agent,
                                             args=(i, layout.agent(), work_objects)))
                  for i in range(n)]
    launched = time.time()
    with MemorySampler() as memory:
        for name, p in processes:
            p.start()
            memory.watch(name, p.pid)
            if name in ("router", "world") and not wait_listening(layout.host, layout.port):
                raise TimeoutError(f"nothing listens on {layout.endpoint} after 30 s")
        try:
            rate, startup, cpu_us, window = results.get(timeout=3 * START_TIMEOUT_S)
        except Exception:  # noqa: BLE001 - a run that hung is reported as nan, not fatal
            rate, startup, cpu_us = float("nan"), float("nan"), float("nan")
            window = (float("nan"), float("nan"))
    stop_all([p for _, p in processes])
    return {"rate": rate, "startup_s": startup - launched, "cpu_us": cpu_us,
            "rss": memory.peaks(), "measured_ticks": ticks - warm_up_ticks(ticks), "window": window}


def stop_all(processes, grace_s: float = 5.0) -> None:
    """Give the processes ``grace_s`` seconds together to end, then kill the rest."""
    deadline = time.monotonic() + grace_s
    for p in processes:
        p.join(max(deadline - time.monotonic(), 0.01))
    for p in processes:
        if p.is_alive():
            p.kill()
            p.join()


def hot_us(objects: int, calls: int = 200, repeats: int = 5) -> float:
    """Microseconds one call of :func:`python_work` over ``objects`` takes hot, in this process
    (the best of ``repeats``)."""
    if not objects:
        return 0.0
    work = python_work(objects)
    return min(timeit.repeat(work, number=calls, repeat=repeats)) / calls * 1e6


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=lambda text: agent_sizes(p, text), default=[8, 32],
                   help="comma-separated agent counts (default: 8,32)")
    p.add_argument("--ticks", type=int, default=2000)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--topology", default="mesh", help=f"comma-separated: {', '.join(TOPOLOGIES)}")
    p.add_argument("--python-work", default="0", metavar="OBJECTS",
                   help="comma-separated: objects of Python each agent's handler reads before it "
                        "answers (a stand-in for a handler's own work; default 0: none)")
    args = p.parse_args()
    topologies = args.topology.split(",")
    if any(t not in TOPOLOGIES for t in topologies):
        p.error(f"topologies are {', '.join(TOPOLOGIES)}")
    try:
        works = [int(v) for v in args.python_work.split(",")]
    except ValueError:
        works = [-1]
    if any(w < 0 for w in works):
        p.error("--python-work is comma-separated numbers of objects, each at least 0")
    loops = [(t, w) for t in topologies for w in works]
    hot = {w: hot_us(w) for w in works}
    print(f"{'agents':>6} {'topology':>11} {'work us':>8} {'ticks/s':>8} {'start s':>8} "
          f"{'CPU us':>7}  runs")
    for n in args.agents:
        results: dict[tuple[str, int], list[dict]] = {loop: [] for loop in loops}
        for _ in range(args.repeats):
            for t, w in loops:  # interleaved, so a drifting machine disturbs them alike
                results[t, w].append(run(n, t, args.ticks, w))
                print(f"  {n} {t}, work {w}: {results[t, w][-1]['rate']:.0f} ticks/s, start-up "
                      f"{results[t, w][-1]['startup_s']:.1f} s", file=sys.stderr, flush=True)
        for t, w in loops:
            rates = [r["rate"] for r in results[t, w]]
            starts = [r["startup_s"] for r in results[t, w]]
            cpu = [r["cpu_us"] for r in results[t, w]]
            print(f"{n:>6} {t:>11} {n * hot[w]:>8.0f} {statistics.median(rates):>8.0f} "
                  f"{statistics.median(starts):>8.2f} {statistics.median(cpu):>7.0f}  "
                  f"{' '.join(f'{x:.0f}' for x in rates)}",
                  flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
