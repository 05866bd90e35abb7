"""The world process: the lockstep clock over Zenoh.

Per tick: publish every agent's observation on ``world/obs/<id>``, in rank order; collect intents
from ``agent/*/intent`` until every live agent has answered or the tick deadline passes (a missing
intent counts as STAY and as a missed intent); apply the tick with ``world.engine``; publish the
next observations; then write the episode row and hand the tick to ``on_tick`` (the launcher logs
it to Rerun there) while the agents already negotiate the next one. Liveliness tokens under
``alive/agent/*`` tell who is live, so a dead agent costs nothing and a stalled one at most the
deadline.

Intents are handled where Zenoh delivers them, on its network thread, under the node's lock: the
last one of a tick closes it there and sends the next observations at once, without waking
another thread (README, "where the time goes"). The main thread does the rest: liveliness, the
deadline, and each closed tick that needs it (an episode's row to write, a broken invariant to
log, ``on_tick``). A tick is closed only once the one before it is written and logged, so
``on_tick`` always sees the world as that tick left it.
"""

import logging
import queue
import signal
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh

from protocol import keys, trace
from protocol.config import SwarmConfig
from protocol.messages import CONTROL_SHUTDOWN, WORLD_SENDER, Control, Inbox, Intent, encode
from protocol.runfiles import EPISODES_FILE, stats_path, write_json_atomic
from protocol.transport import (
    EXIT_TRANSPORT, TransportError, TransportSettings, callback, enqueue, open_session,
)
from world.engine import SwarmWorld, TickReport
from world.metrics import EpisodeWriter

log = logging.getLogger("nnql.world")

BLOCK = zenoh.CongestionControl.BLOCK
"""Lockstep messages are never dropped: through a router one link carries every observation, and
under load Zenoh's default (DROP) lost some, which stalled agents (README, "Several machines")."""

POLL_S = 0.2
"""How often the main thread checks whether it was asked to stop."""

STARTUP_TIMEOUT_S = 60.0
"""How long the world waits for every agent to come alive before it gives up."""


class StartupTimeout(RuntimeError):
    """Not every agent came alive in time."""


@dataclass(frozen=True)
class WorldOptions:
    """How the world process runs."""

    config: SwarmConfig
    transport: TransportSettings
    out_dir: Path
    startup_timeout_s: float = STARTUP_TIMEOUT_S
    first_episode: int = 0
    first_tick: int = 0


class WorldNode:
    """The world's event handlers over its Zenoh session (see the module docstring)."""

    def __init__(self, options: WorldOptions, session: zenoh.Session,
                 on_tick: Callable[[SwarmWorld, TickReport], None] | None = None) -> None:
        self.options = options
        self.config = options.config
        self.session = session
        self.world = SwarmWorld(self.config, options.first_episode, options.first_tick)
        self.inbox = Inbox(self.config.run_id, log)
        self.trace = trace.TickTrace.from_env("world")
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.RLock()
        self.alive: set[int] = set()
        self.stopping = False
        self.failure: BaseException | None = None
        self.on_tick = on_tick
        self.publishers: list = []
        self.actions: list[int | None] | None = None  # the open tick's intents, by agent
        self.tick_start = 0.0
        self.tick_deadline = 0.0
        self.unlogged = 0  # closed ticks handed to the main thread, not yet written and logged
        self.slowest = 0.0  # the episode's slowest tick so far, in seconds
        self.agent_of_key: dict[str, int] = {}  # intent key -> its agent, parsed once

    def stop(self) -> None:
        self.stopping = True
        self.events.put(("stop", None))

    def run(self) -> bool:
        """Run every episode; True if the run completed, False if it was stopped."""
        run_id, s, n = self.config.run_id, self.session, self.config.n_agents
        with (
            s.declare_subscriber(keys.intent_key_all(run_id),
                                 callback(self._on_intent_sample)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              enqueue(self.events, "alive"), history=True),
            s.declare_publisher(keys.control_key(run_id), congestion_control=BLOCK) as control,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_WORLD, 0)),
        ):
            self.publishers = [s.declare_publisher(keys.obs_key(run_id, i), express=True,
                                                   congestion_control=BLOCK) for i in range(n)]
            try:
                self._wait_for_agents()
                completed = self._loop()
            finally:
                with self.lock:
                    self.stopping = True
                control.put(encode(Control(run=run_id, tick=self.world.tick, sender=WORLD_SENDER,
                                           command=CONTROL_SHUTDOWN)))
                for publisher in self.publishers:
                    publisher.undeclare()
        if self.failure is not None:
            raise self.failure
        return completed

    def _wait_for_agents(self) -> None:
        deadline = time.monotonic() + self.options.startup_timeout_s
        while len(self.alive) < self.config.n_agents and not self.stopping:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                missing = sorted(set(range(self.config.n_agents)) - self.alive)
                raise StartupTimeout(f"agents {missing} did not come alive within "
                                     f"{self.options.startup_timeout_s:.0f} s")
            self._handle(timeout=remaining)

    def _loop(self) -> bool:
        """Open the first tick, then handle closed ticks, liveliness and deadlines until the
        last tick is written and logged."""
        world = self.world
        episode_start, episode_tick = time.perf_counter(), world.tick
        with EpisodeWriter(self.options.out_dir / EPISODES_FILE) as writer:
            with self.lock:
                self._open_tick()
            while not self.stopping:
                with self.lock:
                    if world.finished and not self.unlogged:
                        return True
                    self._close_if_due()
                    timeout = min(max(self.tick_deadline - time.monotonic(), 0.0), POLL_S)
                closed = self._handle(timeout)
                if closed is None:
                    continue
                report, slowest, now = closed
                # Unlocked: no tick closes until this one is logged, so the world stays put.
                if report.violations:
                    log.error("tick %d broke the world's invariants: %s", report.tick,
                              report.violations)
                if report.episode_row is not None:
                    writer.write(report.episode_row, now - episode_start, world.tick - episode_tick,
                                 slowest, self.inbox.total_rejected)
                    episode_start, episode_tick = now, world.tick
                if self.on_tick is not None:
                    self.on_tick(world, report)
                with self.lock:
                    self.unlogged -= 1
        return False

    def _open_tick(self) -> None:
        """Send every agent its observation of the current tick; start waiting for intents."""
        self.actions = [None] * self.config.n_agents
        self.learned = {}  # the learning records that came with this tick's intents, by agent
        self.tick_start = time.perf_counter()
        self.tick_deadline = time.monotonic() + self.config.tick_deadline_s
        for obs in self.world.observations_by_rank():  # the first to decide is the first to know
            payload = encode(obs)
            self.trace.mark(trace.OBS_SENT, obs.tick)
            self.publishers[obs.agent].put(payload)

    def _close_if_due(self) -> None:
        """Close the open tick if every live agent's intent is in or its deadline passed, and
        the tick before it is logged."""
        if self.actions is None or self.unlogged or self.stopping:
            return
        if (time.monotonic() >= self.tick_deadline
                or all(self.actions[i] is not None for i in self.alive)):
            self._close_tick()

    def _close_tick(self) -> None:
        """Apply the open tick, open the next (the agents think while this one is logged), and
        hand the report to the main thread if it has anything to do with it: an episode's row,
        a broken invariant, or ``on_tick``. Other ticks do not wake it (a thread switch a tick)."""
        self.trace.mark(trace.CLOSE, self.world.tick)
        report = self.world.apply(self.actions, self.learned)
        now = time.perf_counter()
        self.slowest = max(self.slowest, now - self.tick_start)
        self.actions = None
        if not self.world.finished:
            self._open_tick()
        if report.episode_row is not None or report.violations or self.on_tick is not None:
            self.unlogged += 1  # the main thread writes, logs or records it: wake it
            self.events.put(("closed", (report, self.slowest, now)))
            if report.episode_row is not None:
                self.slowest = 0.0

    def _on_intent_sample(self, sample: zenoh.Sample) -> None:
        """Zenoh callback: keep an intent; the last one of the tick closes it."""
        with self.lock:
            if self.stopping:
                return
            try:
                self._on_intent(sample)
                self._close_if_due()
            except Exception as error:  # noqa: BLE001 - re-raised by run() on the main thread
                self.failure = error
                self.stop()

    def _handle(self, timeout: float):
        """Handle one main-thread event (or none, if ``timeout`` passes first); returns a
        closed tick's ``(report, its duration, when it closed)``, else None."""
        try:
            kind, item = self.events.get(timeout=timeout)
        except queue.Empty:
            return None
        if kind == "closed":
            return item
        if kind == "alive":
            with self.lock:
                self._on_alive(item)
        return None

    def _on_alive(self, sample: zenoh.Sample) -> None:
        agent = keys.agent_from_key(str(sample.key_expr), self.config.run_id)
        if agent is None or agent >= self.config.n_agents:
            self.inbox.reject("unknown-agent", str(sample.key_expr))
        elif sample.kind == zenoh.SampleKind.PUT:
            self.alive.add(agent)
            log.info("agent %d is alive", agent)
        else:
            self.alive.discard(agent)
            log.warning("agent %d left", agent)

    def _on_intent(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        key_agent = self.agent_of_key.get(key)
        if key_agent is None:
            key_agent = keys.agent_from_key(key, self.config.run_id)
            if key_agent is not None and key_agent < self.config.n_agents:
                self.agent_of_key[key] = key_agent  # at most one entry per agent
        intent = self.inbox.decode(sample.payload, Intent, key_agent=key_agent)
        if intent is None:
            return
        tick, actions = self.world.tick, self.actions
        if intent.agent >= self.config.n_agents:
            self.inbox.reject("unknown-agent", f"agent {intent.agent}")
        elif actions is None or intent.tick < tick:
            self.inbox.reject("stale-tick", f"intent for tick {intent.tick} at tick {tick}")
        elif intent.tick > tick:
            self.inbox.reject("future-tick", f"intent for tick {intent.tick} at tick {tick}")
        elif intent.episode != self.world.episode:
            self.inbox.reject("wrong-episode", f"episode {intent.episode}")
        elif actions[intent.agent] is not None:
            self.inbox.reject("duplicate-intent", f"agent {intent.agent} tick {tick}")
        else:
            actions[intent.agent] = intent.action
            if intent.record:
                self.learned[intent.agent] = intent.record[0]


def run_world(options: WorldOptions,
              on_tick: Callable[[SwarmWorld, TickReport], None] | None = None) -> int:
    """Entry point of the world process; returns its exit code."""
    try:
        session = open_session(options.transport)
    except TransportError as error:
        log.error("%s", error)
        return EXIT_TRANSPORT
    with session:
        node = WorldNode(options, session, on_tick)
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: node.stop())
        try:
            completed = node.run()
        except StartupTimeout as error:
            log.error("%s", error)
            return 1
    node.trace.save()
    write_json_atomic(stats_path(options.out_dir, "world"), {
        "completed": completed, "ticks": node.world.tick, "episode": node.world.episode,
        "accepted": node.inbox.accepted, "rejected": dict(node.inbox.rejections),
        "violations": node.world.violations,
    })
    if node.inbox.total_rejected:
        log.warning("world rejected %d messages: %s", node.inbox.total_rejected,
                    dict(node.inbox.rejections))
    if node.world.violations:
        log.error("the world's invariants were broken %d times", node.world.violations)
        return 1
    return 0 if completed else 130
