#!/usr/bin/env python3
"""The swarm's own messages with no work in them: how fast its ticks could go were our Python free.

Two steps, for each size:

1. **Record** which messages a run of the swarm sends at each tick: the real world and agent
   handlers in one thread (``bench.node_cpu``'s harness, every message delivered in the order it
   was sent), the default preset unless ``--preset``, on the grid ``bench.scale`` gives that many
   agents, its first ``--episodes`` episodes. For each tick: the observations the world sends
   (to whom, how large); for each agent that decides, the answers it had when it decided (from
   whom) and what it sent then (answers to whom, its intent), each of its size.
2. **Replay** exactly that pattern with bare processes, started and connected as
   ``bench/lockstep.py`` starts the bare loop (the launcher's start method and layout, one
   session each, handlers on Zenoh's thread): the world sends each tick's observations and waits
   for the tick's intents; an agent, once it has its observation and the answers it waited for,
   answers through the standing queries its neighbours keep open on it and sends its intent,
   and does nothing else. No codec, no rules, no learning, no checks, no files.

Beside each replay, in the same run and interleaved, the bare loop of as many processes. The
replay's ticks a second over every episode but the first, as ``bench.scale`` times the swarm,
is a ceiling: the swarm's tick cannot be cheaper than its own hops. Its ratio to the bare loop
is the most the swarm could reach with every line of our Python taken out of the tick. Both
also report the machine's busy CPU time a tick over the timed ticks (``/proc/stat``): what Zenoh
and the processes' bare loops cost, against which ``bench.tick_cpu``'s figure for the swarm
shows what our Python costs in the processes.

What the recording leaves out makes the ceiling higher, never lower: the asks for one tick to
a neighbour with no standing query yet (counted, and few after the first episode), the replies
to asks for a tick already decided, the end-of-episode checkpoints.

With ``--work-us``, the replay's handlers also work, so that the ratio is told as a function of
what a handler may cost: each agent, once it may decide, and the world, on each intent it
counts, keep their core for that many microseconds of their own thread's CPU time
(:func:`busy`) before they go on (``--working agents`` or ``world``: one side only). A spin
touches almost no memory, as a handler compiled over a few compact arrays would not: the curve
is the budget such a handler has, in the processes, for the ratio the swarm is to reach (the
swarm's own handlers cost some 200 to 300 us a decision and 100 an intent in its processes,
``bench/tick_cpu.py``).

With ``--kernels``, one more replay for each ``--work-us`` whose handlers first do the least a
handler compiled whole would still do, on the recorded run's own data (:class:`KernelWork`):
each agent's decision decodes its observation with the codec, runs the plan's, the neighbour
rows' and the decision's kernels compiled ahead of time on the arguments the agent last passed
them, and encodes its intent; the world decodes each intent and runs the record check's kernel
on the arguments of one of the run's last checks. Unlike a spin it touches what such a handler
touches (the learner's tables, the buffers), on caches the other processes cooled; unlike the
swarm it runs none of the machines' Python, no checks and no bookkeeping. The spin after it
stands for what Python of the machines such a handler would keep.

    python -m bench.pattern --agents 8,64 --repeats 3
    python -m bench.pattern --agents 8,64 --repeats 3 --work-us 0,10,25,50,100,150
    python -m bench.pattern --agents 8,64 --repeats 3 --kernels
    python -m bench.pattern --agents 8,64 --repeats 3 --kernels --work-us 0,25,50
    python -m bench.pattern --agents 64 --repeats 3 --work-us 25,50 --working world
"""

import argparse
import contextlib
import statistics
import struct
import sys
import tempfile
import threading
import time
from collections import Counter, defaultdict
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from bench.kernel_work import KernelWork, capturing
from bench.procstat import TimedTicks

START_TIMEOUT_S = 120.0
_HEAD = struct.Struct("<qi")  # tick, sender (an answer's; 0 in the others)
OPENED = -2  # the tick of a standing query's first reply: it is open
WORKING = ("both", "agents", "world")


@dataclass(frozen=True)
class Decision:
    """What one agent does at one tick: once it has its observation and an answer from each of
    ``awaits``, it sends ``sends`` in order: ``("answer", asker, bytes)`` or
    ``("intent", None, bytes)``."""

    awaits: frozenset[int]
    sends: tuple[tuple[str, int | None, int], ...]

    @property
    def answered(self) -> set[int | None]:
        return {to for kind, to, _ in self.sends if kind == "answer"}

    @property
    def intends(self) -> bool:
        return any(kind == "intent" for kind, _, _ in self.sends)


def played(tick: int, timed_from: int, recorded: int) -> int:
    """The tick of ``recorded`` that a replay's ``tick`` plays: those from ``timed_from`` on are
    played again and again, so that a replay times as many ticks as it is told."""
    if tick < timed_from:
        return tick
    return timed_from + (tick - timed_from) % (recorded - timed_from)


@dataclass
class TickPattern:
    observations: list[tuple[int, int]] = field(default_factory=list)  # (agent, bytes), in order
    decisions: dict[int, Decision] = field(default_factory=dict)

    @property
    def intents(self) -> int:
        return sum(1 for d in self.decisions.values() if d.intends)


@dataclass
class Pattern:
    """A run's messages, tick by tick; ``timed_from``: the first tick of the second episode."""

    n: int
    ticks: list[TickPattern]
    timed_from: int
    asks: int = 0  # asks for one tick, after the first episode (left out of the replay)
    late_replies: int = 0  # replies to asks for a tick already decided (left out)

    def recorded(self, tick: int) -> int:
        """The recorded tick a replay's ``tick`` plays (:func:`played`)."""
        return played(tick, self.timed_from, len(self.ticks))

    def answers_per_tick(self) -> float:
        timed = self.ticks[self.timed_from:]
        return sum(1 for t in timed for d in t.decisions.values() for kind, _, _ in d.sends
                   if kind == "answer") / max(len(timed), 1)

    def hops_per_tick(self) -> float:
        """The hops on each tick's longest chain (the observation, each answer waited for, the
        intent), averaged over the timed ticks: the bare loop's is 2."""
        hops = []
        for tick in self.ticks[self.timed_from:]:
            depth: dict[int, int] = {}

            def chain(agent: int, seen: frozenset = frozenset()) -> int:
                if agent not in depth:
                    decision = tick.decisions.get(agent)
                    awaited = decision.awaits - seen - {agent} if decision else frozenset()
                    depth[agent] = 1 + max((chain(a, seen | {agent}) for a in awaited),
                                           default=0)
                return depth[agent]

            senders = [a for a, d in tick.decisions.items() if d.intends]
            hops.append(1 + max((chain(a) for a in senders), default=0))
        return statistics.mean(hops) if hops else 0.0


def record(config, work: KernelWork | None = None) -> Pattern:
    """The messages of a run of ``config`` through the real handlers (see the module
    docstring); with ``work``, what its compiled handlers would still do, kept into it."""
    from bench import node_cpu
    from nnql_swarm.protocol.messages import Answer, Intent, Observation, parse

    run_id = config.run_id
    observations: dict[int, list[tuple[int, int]]] = defaultdict(list)
    answers_to: dict[tuple[int, int], list[tuple[int, int]]] = defaultdict(list)
    sends: dict[tuple[int, int], list[tuple[int, str, int | None, int]]] = defaultdict(list)
    episodes: dict[int, int] = {}
    asks_at: Counter[int] = Counter()

    def on_send(number, kind, sender, receiver, item, cause) -> None:
        if kind == "observation":
            msg = parse(item.payload, Observation, run_id)
            observations[msg.tick].append((receiver, len(item.payload)))
            episodes.setdefault(msg.tick, msg.episode)
            if work is not None:
                work.observations[receiver] = item.payload
        elif kind == "intent":
            msg = parse(item.payload, Intent, run_id)
            sends[sender, msg.tick].append((cause, "intent", None, len(item.payload)))
            if work is not None and (msg.record or msg.agent not in work.intents):
                work.intents[msg.agent] = item.payload  # one with a record, where it sent one
        elif kind == "answer":
            payload = item.ok.payload
            msg = parse(payload, Answer, run_id)
            answers_to[receiver, msg.tick].append((number, sender))
            sends[sender, msg.tick].append((cause, "answer", receiver, len(payload)))
        elif kind == "query" and "tick=" in item.parameters:
            asks_at[int(item.parameters.split("tick=")[1].split(";")[0])] += 1

    with tempfile.TemporaryDirectory() as tmp, \
            capturing(work) if work is not None else contextlib.nullcontext():
        ticks, _ = node_cpu.run(config, Path(tmp), False, on_send=on_send)
    pattern = Pattern(config.n_agents, [TickPattern() for _ in range(ticks)],
                      timed_from=min((t for t, e in episodes.items() if e >= 1), default=0))
    for tick, observed in observations.items():
        if tick < ticks:
            pattern.ticks[tick].observations = observed
    for (agent, tick), sent in sends.items():
        if tick >= ticks:
            continue
        decided = sent[0][0]  # the message whose handler decided: its first send's cause
        awaits = frozenset(s for number, s in answers_to[agent, tick] if number <= decided)
        pattern.ticks[tick].decisions[agent] = Decision(
            awaits, tuple((kind, to, size) for cause, kind, to, size in sent if cause == decided))
        if tick >= pattern.timed_from:
            pattern.late_replies += sum(1 for cause, *_ in sent if cause != decided)
    # An answer its sender did not send with its decision (a reply to an ask for a tick it had
    # decided) is left out, and so is waiting for it.
    for tick in pattern.ticks:
        decisions = tick.decisions
        for agent, decision in decisions.items():
            sent = frozenset(s for s in decision.awaits
                             if s in decisions and agent in decisions[s].answered)
            if sent != decision.awaits:
                decisions[agent] = Decision(sent, decision.sends)
    pattern.asks = sum(count for tick, count in asks_at.items() if tick >= pattern.timed_from)
    return pattern


def busy(seconds: float) -> None:
    """Keep the core for ``seconds`` of this thread's own CPU time (not the wall clock's: time
    another process holds the core is not work): the stand-in for a handler's work."""
    if seconds > 0:
        end = time.thread_time() + seconds
        while time.thread_time() < end:
            pass


def _payload(tick: int, size: int, sender: int = 0) -> bytes:
    head = _HEAD.pack(tick, sender)
    return head + bytes(max(size - len(head), 0))


def agent(me: int, script: dict[int, Decision], recorded, transport,
          timeout_s: float = START_TIMEOUT_S, work_s: float = 0.0,
          kernels: KernelWork | None = None) -> None:
    """One agent of the replay: at each tick, once its observation and awaited answers are in,
    it does its compiled decision's work where ``kernels`` holds one
    (:meth:`KernelWork.agent_work`) and works ``work_s`` (:func:`busy`), then sends what it sent
    at the tick it plays (``recorded(tick)``: :func:`played`); it leaves on a negative tick
    (:func:`replay` stops it if its world gave up)."""
    from nnql_swarm.transport.callbacks import callback
    from nnql_swarm.transport.runtime import declare_lockstep_publisher
    from nnql_swarm.transport.settings import open_session
    import zenoh

    compiled = kernels.agent_work(me) if kernels is not None else None
    answerers = {a for d in script.values() for a in d.awaits}
    lock = threading.Lock()
    done, everyone_up, streamed = threading.Event(), threading.Event(), threading.Event()
    up: set[str] = set()
    unconfirmed = set(answerers)  # the neighbours whose standing queries are not open yet
    if not unconfirmed:
        streamed.set()
    standing: dict[int, object] = {}  # asker -> its standing query on this agent
    unsent: dict[int, list[bytes]] = defaultdict(list)  # answers owed before the query came
    observed: set[int] = set()
    heard: dict[int, set[int]] = defaultdict(set)
    with open_session(transport) as s:
        publisher = declare_lockstep_publisher(s, f"pat/intent/{me}")
        key = f"pat/intent/{me}"

        def reply(asker: int, payload: bytes) -> None:
            query = standing.get(asker)
            if query is None:
                unsent[asker].append(payload)
            else:
                query.reply(key, payload)

        def try_decide(tick: int) -> None:
            decision = script.get(recorded(tick))
            if tick not in observed or decision is None or not decision.awaits <= heard[tick]:
                return
            observed.discard(tick)
            heard.pop(tick, None)
            if compiled is not None:
                compiled()
            busy(work_s)
            for kind, to, size in decision.sends:
                if kind == "answer":
                    reply(to, _payload(tick, size, me))
                else:
                    publisher.put(_payload(tick, size))

        def on_obs(sample) -> None:
            tick, _ = _HEAD.unpack_from(sample.payload.to_bytes())
            if tick < 0:
                done.set()
                return
            with lock:
                observed.add(tick)
                try_decide(tick)

        def on_answer(reply_) -> None:
            if reply_.ok is None:
                return
            tick, sender = _HEAD.unpack_from(reply_.ok.payload.to_bytes())
            with lock:
                if tick == OPENED:
                    unconfirmed.discard(sender)
                    if not unconfirmed:
                        streamed.set()
                else:
                    heard[tick].add(sender)
                    try_decide(tick)

        def on_query(query) -> None:
            asker = int(str(query.parameters).split("from=")[1])
            with lock:
                standing[asker] = query
                query.reply(key, _payload(OPENED, 0, me))
                for payload in unsent.pop(asker, []):
                    query.reply(key, payload)

        def on_up(sample) -> None:
            with lock:
                up.add(str(sample.key_expr))
                if everyone <= up:
                    everyone_up.set()

        everyone = {f"pat/up/{a}" for a in answerers}
        s.declare_subscriber(f"pat/obs/{me}", callback(on_obs))
        s.declare_queryable(key, callback(on_query))
        tokens = [s.liveliness().declare_token(f"pat/up/{me}")]
        s.liveliness().declare_subscriber("pat/up/*", callback(on_up), history=True)
        if not everyone:
            everyone_up.set()
        everyone_up.wait(timeout_s)
        # A query sent before this session has heard of the neighbour's queryable ends at once,
        # unanswered, and one may wait long in a crowd: each is sent again, later each time,
        # until its neighbour says it is open (the newest query it got is the one it answers).
        deadline = time.monotonic() + timeout_s
        ask_at = dict.fromkeys(answerers, 0.0)  # answerer -> when to ask it (again)
        backoff = dict.fromkeys(answerers, 0.2)
        while not streamed.is_set() and time.monotonic() < deadline:
            now = time.monotonic()
            with lock:
                due = sorted(a for a in unconfirmed if ask_at[a] <= now)
            for a in due:
                s.get(f"pat/intent/{a}?from={me}", callback(on_answer),
                      consolidation=zenoh.ConsolidationMode.NONE, timeout=10 * timeout_s)
                ask_at[a], backoff[a] = now + backoff[a], min(2 * backoff[a], 3.0)
            streamed.wait(0.05)
        tokens.append(s.liveliness().declare_token(f"pat/ready/{me}"))
        done.wait()
        for token in tokens:
            token.undeclare()
        time.sleep(0.2)


def world(n: int, ticks: list[tuple[list[tuple[int, int]], int]], recorded, total: int,
          timed_from: int, transport, results, timeout_s: float = START_TIMEOUT_S,
          work_s: float = 0.0, kernels: KernelWork | None = None) -> None:
    """The replay's clock: ``total`` ticks, each the observations of the tick it plays
    (``recorded(tick)``, into ``ticks``) out and its intents in, working ``work_s`` on each
    intent (:func:`busy`), after a compiled handler's work where ``kernels`` holds it
    (:meth:`KernelWork.world_work`); puts ``(ticks a second from
    ``timed_from``, the time every agent was ready, the machine's busy CPU microseconds a tick
    from ``timed_from``)`` on ``results``."""
    from nnql_swarm.transport.callbacks import callback
    from nnql_swarm.transport.runtime import declare_lockstep_publisher
    from nnql_swarm.transport.settings import open_session

    compiled = kernels.world_work() if kernels is not None else None
    ready: set[str] = set()
    everyone, finished = threading.Event(), threading.Event()
    state = {"tick": 0, "heard": 0}
    timed = TimedTicks()
    with open_session(transport) as s:
        pubs = [declare_lockstep_publisher(s, f"pat/obs/{i}") for i in range(n)]

        def open_tick(tick: int) -> None:
            while True:
                if tick == timed_from:
                    timed.start()
                if tick == total:
                    finished.set()
                    return
                observed, intents = ticks[recorded(tick)]
                state["tick"], state["heard"] = tick, 0
                for to, size in observed:
                    pubs[to].put(_payload(tick, size))
                if intents:
                    return
                tick += 1  # nobody owes this tick an intent

        def on_intent(sample) -> None:
            tick, _ = _HEAD.unpack_from(sample.payload.to_bytes())
            if tick != state["tick"]:
                return
            if compiled is not None:
                compiled()
            busy(work_s)
            state["heard"] += 1
            if state["heard"] == ticks[recorded(tick)][1]:
                open_tick(tick + 1)

        def on_ready(sample) -> None:
            ready.add(str(sample.key_expr))
            if len(ready) == n:
                everyone.set()

        s.declare_subscriber("pat/intent/*", callback(on_intent))
        s.liveliness().declare_subscriber("pat/ready/*", callback(on_ready), history=True)
        if not everyone.wait(timeout_s):
            print(f"world: only {len(ready)} of {n} agents ready", file=sys.stderr, flush=True)
            results.put((float("nan"), float("nan"), float("nan")))
            return
        startup = time.time()
        time.sleep(0.5)  # let the standing queries settle before the clock starts
        open_tick(0)
        if not finished.wait(5 * timeout_s):
            print(f"world: stalled at tick {state['tick']} (plays {recorded(state['tick'])}), "
                  f"{state['heard']} intents of {ticks[recorded(state['tick'])][1]}",
                  file=sys.stderr, flush=True)
            results.put((float("nan"), startup, float("nan")))
        else:
            rate, cpu_us = timed.measure(total - timed_from)
            results.put((rate, startup, cpu_us))
        for pub in pubs:
            pub.put(_payload(-1, 0))
        time.sleep(0.3)


def replay(pattern: Pattern, topology: str, timed_ticks: int,
           timeout_s: float | None = None, work_us: float = 0.0,
           working: str = "both", kernels: KernelWork | None = None) -> dict:
    """One replay of ``pattern``, its ticks from the second episode on played until
    ``timed_ticks`` are timed, each handler that carries the model working ``work_us`` (each
    agent's decision, each intent the world counts: :func:`busy`), after a compiled handler's
    work where ``kernels`` holds it; ``working``: ``both``, or only the ``agents`` or the
    ``world``: ``rate`` (ticks a second over those; nan if its
    agents were not ready within ``timeout_s``, by default :data:`START_TIMEOUT_S` or half a
    second an agent, or it stalled for five times that), ``startup_s`` (until every agent was
    ready), ``cpu_us`` (the machine's busy CPU microseconds a tick over the timed ticks)."""
    if timeout_s is None:
        timeout_s = max(START_TIMEOUT_S, pattern.n / 2)
    from bench.lockstep import stop_all
    from nnql_swarm.launch.processes import process_context
    from nnql_swarm.transport.ports import wait_listening
    from nnql_swarm.transport.topology import EmbeddedLayout

    ctx = process_context()
    layout = EmbeddedLayout(topology=topology)
    results = ctx.Queue()
    scripts: list[dict[int, Decision]] = [{} for _ in range(pattern.n)]
    for tick, tp in enumerate(pattern.ticks):
        for a, decision in tp.decisions.items():
            scripts[a][tick] = decision
    clock = [(tp.observations, tp.intents) for tp in pattern.ticks]
    work_s = work_us / 1e6
    processes = []
    if layout.router() is not None:
        from bench.lockstep import router

        processes.append(ctx.Process(target=router, args=(layout.router(),)))
    total = pattern.timed_from + timed_ticks
    recorded = partial(played, timed_from=pattern.timed_from, recorded=len(pattern.ticks))
    world_works, agents_work = working != "agents", working != "world"
    processes.append(ctx.Process(target=world, args=(
        pattern.n, clock, recorded, total, pattern.timed_from, layout.world(), results,
        timeout_s, work_s if world_works else 0.0,
        kernels.part(None) if kernels is not None and world_works else None)))
    processes += [ctx.Process(target=agent, args=(
        i, scripts[i], recorded, layout.agent(), timeout_s, work_s if agents_work else 0.0,
        kernels.part(i) if kernels is not None and agents_work else None))
        for i in range(pattern.n)]
    launched = time.time()
    for i, p in enumerate(processes):
        p.start()
        if i < len(processes) - pattern.n and not wait_listening(layout.host, layout.port):
            raise TimeoutError(f"nothing listens on {layout.endpoint} after 30 s")
    try:
        rate, startup, cpu_us = results.get(timeout=8 * timeout_s)
    except Exception:  # noqa: BLE001 - a replay that hung is reported as nan, not fatal
        rate, startup, cpu_us = float("nan"), float("nan"), float("nan")
    stop_all(processes)
    return {"rate": rate, "startup_s": startup - launched, "cpu_us": cpu_us}


def work_label(work: tuple[float, bool]) -> str:
    """A row's work a handler: the compiled handler's, if it does it, and microseconds of
    spinning."""
    spin, compiled = work
    return f"kernels + {spin:g} us" if compiled else f"{spin:g} us"


def main() -> int:
    from bench.harness import add_preset_option, agent_sizes, grid_side, swarm_config
    from bench.scale import bare_once, median
    from nnql_swarm.transport.topology import embedded_topology

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", default="8,64", help="comma-separated agent counts")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--episodes", type=int, default=6,
                   help="episodes recorded and replayed (the first is not timed)")
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--ticks", type=int, default=2000, help="ticks timed in each replay (the "
                   "recorded ticks from the second episode on, again and again) and in each "
                   "bare loop")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--work-us", default="0", help="comma-separated microseconds of CPU each "
                   "agent's decision and each of the world's intents cost in the replay (busy "
                   "spinning): one row each")
    p.add_argument("--kernels", action="store_true",
                   help="one more row for each --work-us: the handlers first doing a compiled "
                        "handler's least work on the run's own data (the codec and the "
                        "kernels)")
    p.add_argument("--working", choices=WORKING, default="both",
                   help="whose handlers work: every agent's decision and the world's intents, "
                        "or only one side's")
    add_preset_option(p)
    args = p.parse_args()
    sizes = agent_sizes(p, args.agents)
    if args.repeats < 1 or args.episodes < 2 or args.ticks < 1:
        p.error("need --repeats >= 1, --episodes >= 2 and --ticks >= 1")
    try:
        works = [float(w) for w in args.work_us.split(",")]
    except ValueError:
        p.error(f"--work-us takes comma-separated microseconds, not {args.work_us!r}")
    if any(not 0 <= w < 1e6 for w in works):
        p.error(f"--work-us must be between 0 and 1,000,000 microseconds, not {args.work_us}")
    rows: list[tuple[int | float | str, ...]] = []
    kinds = [(w, False) for w in works] + [(w, True) for w in works if args.kernels]
    for n in sizes:
        side = grid_side(n)
        try:
            config = swarm_config(args.preset, run_id=f"pattern-{n}", n_agents=n, width=side,
                                  height=side, episodes=args.episodes,
                                  max_steps=args.max_steps, seed=args.seed)
        except ValueError as error:
            p.error(f"{n} agents: {error}")
        kernel_work = KernelWork(config.run_id) if args.kernels else None
        pattern = record(config, kernel_work)
        print(f"  {n} agents: {len(pattern.ticks)} ticks recorded, {pattern.timed_from} in the "
              f"first episode; {pattern.answers_per_tick():.2f} answers and "
              f"{pattern.hops_per_tick():.2f} hops on the longest chain a tick; "
              f"{pattern.asks} asks for one tick and {pattern.late_replies} late replies "
              f"left out", file=sys.stderr, flush=True)
        topology = embedded_topology(n)
        replays: dict[tuple[float, bool], list[dict]] = {w: [] for w in kinds}
        bares: list[dict] = []
        for repeat in range(args.repeats):  # each repeat's bare loop among its replays
            for w in kinds:
                replays[w].append(replay(pattern, topology, args.ticks, work_us=w[0],
                                         working=args.working,
                                         kernels=kernel_work if w[1] else None))
                print(f"  {n} agents, repeat {repeat + 1}, {work_label(w)} a handler: the "
                      f"pattern {replays[w][-1]['rate']:.0f} ticks/s", file=sys.stderr,
                      flush=True)
            bares.append(bare_once(n, args.ticks, topology))
            print(f"  {n} agents, repeat {repeat + 1}: bare {bares[-1]['rate']:.0f} ticks/s",
                  file=sys.stderr, flush=True)
        for w in kinds:
            ratios = [r["rate"] / b["rate"] for r, b in zip(replays[w], bares)]
            rows.append((n, topology, pattern, w, statistics.median(r["rate"] for r in replays[w]),
                         statistics.median(b["rate"] for b in bares), statistics.median(ratios),
                         replays[w], bares))
    print(f"preset {args.preset}, {args.episodes} episodes of at most {args.max_steps} steps, "
          f"medians of {args.repeats}; working: {args.working}")
    print("| agents | topology | hops a tick (bare: 2) | answers a tick | work a handler | "
          "the pattern, ticks/s | bare, ticks/s | ratio | CPU us a tick, the pattern | bare | "
          "runs (pattern; bare) |")
    print("| ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for n, topology, pattern, w, rate, bare, ratio, replays_w, bares in rows:
        print(f"| {n} | {topology} | {pattern.hops_per_tick():.2f} | "
              f"{pattern.answers_per_tick():.2f} | {work_label(w)} | {rate:.0f} | {bare:.0f} | "
              f"{ratio:.2f} | {median(replays_w, 'cpu_us'):.0f} | {median(bares, 'cpu_us'):.0f} | "
              f"{' '.join(format(r['rate'], '.0f') for r in replays_w)}; "
              f"{' '.join(format(b['rate'], '.0f') for b in bares)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
