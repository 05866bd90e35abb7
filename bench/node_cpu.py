#!/usr/bin/env python3
"""The Python cost of a tick in the nodes themselves, with Zenoh taken out, in one process.

The real ``AgentNode`` and ``WorldNode`` handlers (the adapters and the protocol machines under
them) run in one thread, over a stand-in for Zenoh that delivers every message (observation,
standing query, answer, intent) in the order it was sent, by calling the receiver's handler
directly. What is timed is exactly our code on each message: decoding, checks, negotiation,
learning, encoding, the world's rules, carrying out the effects; not Zenoh, the kernel or the
scheduler. Each handler is timed apart (the last intent's includes closing the tick: the
rules and the next observations; it is also timed on its own, as the closing intent: the world's
stretch in which every agent waits for it), so the tick's critical path (world -> rank 0 -> ...
-> rank N-1 -> world) can be added up from them.

On a small shared machine the swarm's speed drifts within minutes; this figure drifts much
less, but it is still best compared between runs made one after the other. It counts what runs
hot in one process: in the swarm, each process wakes from cold caches and the same code takes
about twice as long (docs/performance.md). With ``--cpu-time`` each handler is timed by its
thread's CPU time: the time other processes take the cores, and the checkpoints' waits for the
disk, drop out (what those processes do to the caches does not). With ``--cold-caches``, before
each message (outside the timed part) a buffer larger than a core's L2 cache is written over
(:class:`CacheEvictor`): each handler then starts on caches other work has cooled, as a swarm
process does when it wakes, and the same code costs what it costs in the swarm.

    python -m bench.node_cpu --agents 8 --episodes 20 --repeats 5
    python -m bench.node_cpu --agents 8 --episodes 20 --repeats 7 --cpu-time
    python -m bench.node_cpu --agents 8 --episodes 10 --repeats 3 --cpu-time --cold-caches
"""

import argparse
import collections
import contextlib
import mmap
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NNQL_KERNEL", "python")  # as in the swarm's processes, unless told

import numpy as np
import zenoh

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.agent_node import AgentNode, AgentOptions
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.actions import STAY
from bench.harness import add_preset_option, grid_side, swarm_config
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.settings import TransportSettings
from nnql_swarm.world.world_node import WorldNode, WorldOptions


class _Callback:
    """Stands in for ``zenoh.handlers.Callback``: keeps the function."""

    def __init__(self, callback, drop=None, indirect=True) -> None:
        self.callback, self.drop = callback, drop


class _Ok:
    def __init__(self, payload: bytes) -> None:
        self.payload = payload


class _Reply:
    def __init__(self, payload: bytes) -> None:
        self.ok = _Ok(payload)


class _Sample:
    def __init__(self, key: str, payload: bytes) -> None:
        self.key_expr, self.payload = key, payload


class CacheEvictor:
    """Cools a core's private caches: writes over a buffer of ``factor`` times its L2 cache (as
    Linux tells it; 2 MiB where it does not), so that what a handler reads next comes from the
    shared cache or from memory, as after another process ran on the core."""

    def __init__(self, factor: int = 4) -> None:
        # its own mapping: in small pages whatever the allocator's settings, so that it also
        # cools as much of the TLB each time
        self._map = mmap.mmap(-1, factor * l2_cache_bytes())
        self.buffer = np.frombuffer(self._map, dtype=np.float64)

    def __call__(self) -> None:
        self.buffer += 1.0


def l2_cache_bytes(default: int = 2 << 20) -> int:
    """The size of the first CPU's level-2 cache, from ``/sys``; ``default`` where it is not told."""
    for index in Path("/sys/devices/system/cpu/cpu0/cache").glob("index*"):
        try:
            if (index / "level").read_text().strip() == "2":
                size = (index / "size").read_text().strip()
                shift = {"K": 10, "M": 20}.get(size[-1:], 0)
                return int(size[:-1] if shift else size) << shift
        except (OSError, ValueError):
            pass
    return default


WORLD = -1
"""The world's number where a message's sender or receiver is told (agents are 0 .. N - 1)."""


class Wire:
    """Every message sent, delivered in order; each delivery timed by the handler's kind, on
    ``clock``. ``on_send(number, kind, sender, receiver, item, cause)``, if given, is told each
    message as it is sent: its number (messages are delivered in the order of their numbers),
    who sends it to whom (:data:`WORLD`, an agent, or None: everyone, or nobody in particular),
    and the number of the message whose handler sent it (-1: none). ``before_each()``, if given,
    runs before each delivery, outside its timing (:class:`CacheEvictor`)."""

    def __init__(self, clock=time.perf_counter, on_send=None, before_each=None) -> None:
        self.clock = clock
        self.on_send = on_send
        self.before_each = before_each
        self.queue: collections.deque = collections.deque()
        self.subscribers: dict[str, list] = collections.defaultdict(list)
        self.queryables: dict[str, object] = {}
        self.owners: dict[str, int] = {}  # an agent's intent key -> the agent
        self.seconds: collections.Counter = collections.Counter()
        self.count: collections.Counter = collections.Counter()
        self.closing_seconds, self.closing = 0.0, 0  # the intents that closed a tick, among them
        self.sent = 0
        self.observations = 0  # observations sent so far
        self.handling, self.handler_of = -1, None  # the message being handled, its receiver

    def send(self, kind: str, handler, item, receiver: int | None = None) -> None:
        number, self.sent = self.sent, self.sent + 1
        self.observations += kind == "observation"
        self.queue.append((kind, handler, item, number, receiver))
        if self.on_send is not None:
            self.on_send(number, kind, self.handler_of, receiver, item, self.handling)

    def drain(self) -> None:
        clock, before_each = self.clock, self.before_each
        while self.queue:
            kind, handler, item, self.handling, self.handler_of = self.queue.popleft()
            if before_each is not None:
                before_each()
            observations = self.observations
            start = clock()
            handler(item)
            spent = clock() - start
            self.seconds[kind] += spent
            self.count[kind] += 1
            if kind == "intent" and self.observations > observations:  # it closed the tick
                self.closing_seconds += spent
                self.closing += 1
        self.handling, self.handler_of = -1, None


class _Publisher:
    def __init__(self, wire: Wire, key: str, kind: str, receiver: int | None = None) -> None:
        self.wire, self.key, self.kind, self.receiver = wire, key, kind, receiver

    def put(self, payload: bytes) -> None:
        for handler in self.wire.subscribers[self.key]:
            self.wire.send(self.kind, handler, _Sample(self.key, payload), self.receiver)

    def undeclare(self) -> None:
        pass


class _Query:
    def __init__(self, wire: Wire, key: str, parameters: str, handler, asker: int) -> None:
        self.wire, self.key_expr, self.parameters, self.handler = wire, key, parameters, handler
        self.asker = asker

    def reply(self, key, payload: bytes) -> None:
        self.wire.send("answer", self.handler.callback, _Reply(payload), self.asker)

    def reply_err(self, payload: bytes) -> None:
        pass

    def drop(self) -> None:
        if self.handler.drop is not None:
            self.wire.send("query end", lambda _: self.handler.drop(), None, self.asker)


class _Session:
    """What the nodes call on their session, in the harness: ``get`` and nothing else.
    ``owner``: the node's number (:data:`WORLD` or its agent)."""

    def __init__(self, wire: Wire, owner: int) -> None:
        self.wire, self.owner = wire, owner

    def get(self, selector: str, handler, **_) -> None:
        key, _, parameters = selector.partition("?")
        self.wire.send("query", self.wire.queryables[key],
                       _Query(self.wire, key, parameters, handler, self.owner),
                       self.wire.owners[key])


class _LearnNothing(AgentBrain):
    def act(self, obs, answers, seen=(None, None)) -> int:
        return STAY


def _ends_of_asks(agents: list[AgentNode]) -> None:
    """Hand each agent the ends of its asks, which its node queues for its main thread (a
    standing query its neighbour ended, once far for long enough: ``agent.answering``)."""
    for node in agents:
        while not node.events.empty():
            kind, item = node.events.get()
            if kind == "ask-end":
                node.feed(node.protocol.on_ask_end, item)


def run(config: SwarmConfig, out: Path, bare: bool,
        clock=time.perf_counter, on_send=None, before_each=None) -> tuple[int, Wire]:
    """Run ``config`` through the real handlers over a :class:`Wire` timed on ``clock``, telling
    ``on_send`` each message and running ``before_each`` before each (:class:`Wire`); (ticks,
    the wire)."""
    with _stand_in_callbacks():
        return _run(config, out, bare, Wire(clock, on_send, before_each))


@contextlib.contextmanager
def _stand_in_callbacks():
    """``zenoh.handlers.Callback`` is :class:`_Callback` inside, as it was again after: the nodes
    build their handlers at call time, and other code of the same process (a test run's) needs
    the real one."""
    real = zenoh.handlers.Callback
    zenoh.handlers.Callback = _Callback
    try:
        yield
    finally:
        zenoh.handlers.Callback = real


def _run(config: SwarmConfig, out: Path, bare: bool, wire: Wire) -> tuple[int, Wire]:
    transport = TransportSettings()
    run_id, n = config.run_id, config.n_agents
    world = WorldNode(WorldOptions(config, transport, out), _Session(wire, WORLD))
    world.publishers = [_Publisher(wire, keys.obs_key(run_id, i), "observation", i)
                        for i in range(n)]
    world.control = _Publisher(wire, keys.control_key(run_id), "control")
    agents = []
    for i in range(n):
        brain = (_LearnNothing if bare else AgentBrain)(i, config)
        node = AgentNode(AgentOptions(i, config, transport, out), _Session(wire, i), brain)
        for j in range(n):
            node.feed(node.protocol.on_liveliness, keys.alive_key(run_id, keys.ROLE_AGENT, j), True)
        intent_key = keys.intent_key(run_id, i)
        node.publisher = _Publisher(wire, intent_key, "intent", WORLD)
        wire.subscribers[intent_key].append(world._on_intent)
        wire.subscribers[keys.obs_key(run_id, i)].append(node._on_observation)
        wire.queryables[intent_key] = node._on_query
        wire.owners[intent_key] = i
        agents.append(node)
    for i in range(n):  # the last one opens the first tick
        world.feed(world.protocol.on_liveliness, keys.alive_key(run_id, keys.ROLE_AGENT, i), True)
    while not world.world.finished:
        if not wire.queue:
            _ends_of_asks(agents)
        if not wire.queue:
            raise RuntimeError(f"nothing to deliver at tick {world.world.tick}")
        wire.drain()
    for node in (*agents, world):
        if node.failure is not None:
            raise node.failure
    return world.world.tick, wire


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=5)
    add_preset_option(p)
    p.add_argument("--bare", action="store_true", help="agents learn nothing and stay")
    p.add_argument("--cpu-time", action="store_true",
                   help="time by the thread's CPU time rather than the wall clock: steadier on "
                        "a shared machine, and without the checkpoints' waits for the disk")
    p.add_argument("--cold-caches", action="store_true",
                   help="write over a buffer four times a core's L2 cache before each message: each "
                        "handler starts on cooled caches, as in the swarm's processes")
    args = p.parse_args()
    n = args.agents
    config = swarm_config(args.preset, run_id="cpu", n_agents=n, episodes=args.episodes,
                          max_steps=args.max_steps, width=grid_side(n), height=grid_side(n))
    per_tick: dict[str, list[float]] = collections.defaultdict(list)
    for r in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            ticks, wire = run(config, Path(tmp), args.bare,
                              time.thread_time if args.cpu_time else time.perf_counter,
                              before_each=CacheEvictor() if args.cold_caches else None)
        for kind in wire.seconds:
            per_tick[kind].append(1e6 * wire.seconds[kind] / ticks)
        per_tick["whole tick"].append(1e6 * sum(wire.seconds.values()) / ticks)
        per_message = {k: 1e6 * wire.seconds[k] / wire.count[k] for k in wire.seconds}
        if wire.closing:
            per_message["closing intent"] = 1e6 * wire.closing_seconds / wire.closing
        for kind, us in per_message.items():
            per_tick[f"one {kind}"].append(us)
    caches = ", each message on cooled caches" if args.cold_caches else ""
    print(f"{n} agents, {ticks} ticks a repeat, {args.repeats} repeats{caches}; us (median over "
          "repeats)")
    for kind in sorted(per_tick, key=lambda k: (not k.startswith("one "), k)):
        values = per_tick[kind]
        print(f"  {kind:<22} {statistics.median(values):8.1f}  "
              f"({' '.join(f'{v:.1f}' for v in values)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
