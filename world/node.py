"""The world process: the lockstep clock over Zenoh.

Per tick: publish every agent's observation on ``world/obs/<id>``, in rank order; collect intents
from ``agent/*/intent`` until every live agent has answered or the tick deadline passes (a missing
intent counts as STAY and as a missed intent); apply the tick with ``world.engine``; write the
episode row; hand each tick to ``on_tick`` (the launcher logs it to Rerun there). Liveliness
tokens under ``alive/agent/*`` tell who is live, so a dead agent costs nothing and a stalled one
at most the deadline. Zenoh callbacks only keep what arrives (intents in a list, other events in
a queue); all work is on the main thread.
"""

import logging
import queue
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh

from protocol import keys
from protocol.config import SwarmConfig
from protocol.messages import CONTROL_SHUTDOWN, WORLD_SENDER, Control, Inbox, Intent, encode
from protocol.runfiles import EPISODES_FILE, stats_path, write_json_atomic
from protocol.transport import (
    EXIT_TRANSPORT, TransportError, TransportSettings, enqueue, open_session,
)
from world.engine import SwarmWorld, TickReport
from world.metrics import EpisodeWriter

log = logging.getLogger("nnql.world")

BLOCK = zenoh.CongestionControl.BLOCK
"""Lockstep messages are never dropped: through a router one link carries every observation, and
under load Zenoh's default (DROP) lost some, which stalled agents (README, "Several machines")."""

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
    """The world's event loop over its Zenoh session."""

    def __init__(self, options: WorldOptions, session: zenoh.Session,
                 on_tick: Callable[[SwarmWorld, TickReport], None] | None = None) -> None:
        self.options = options
        self.config = options.config
        self.session = session
        self.world = SwarmWorld(self.config, options.first_episode, options.first_tick)
        self.inbox = Inbox(self.config.run_id, log)
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.alive: set[int] = set()
        self.stopping = False
        self.on_tick = on_tick
        self.intent_samples: list[zenoh.Sample] = []
        self.wake_at = 1

    def stop(self) -> None:
        self.stopping = True
        self.events.put(("stop", None))

    def run(self) -> bool:
        """Run every episode; True if the run completed, False if it was stopped."""
        run_id, s, n = self.config.run_id, self.session, self.config.n_agents
        with (
            s.declare_subscriber(keys.intent_key_all(run_id),
                                 zenoh.handlers.Callback(self._keep_intent, indirect=False)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              enqueue(self.events, "alive"), history=True),
            s.declare_publisher(keys.control_key(run_id), congestion_control=BLOCK) as control,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_WORLD, 0)),
        ):
            publishers = [s.declare_publisher(keys.obs_key(run_id, i), express=True,
                                              congestion_control=BLOCK) for i in range(n)]
            try:
                self._wait_for_agents()
                completed = self._loop(publishers)
            finally:
                control.put(encode(Control(run=run_id, tick=self.world.tick, sender=WORLD_SENDER,
                                           command=CONTROL_SHUTDOWN)))
                for publisher in publishers:
                    publisher.undeclare()
        return completed

    def _wait_for_agents(self) -> None:
        deadline = time.monotonic() + self.options.startup_timeout_s
        while len(self.alive) < self.config.n_agents and not self.stopping:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                missing = sorted(set(range(self.config.n_agents)) - self.alive)
                raise StartupTimeout(f"agents {missing} did not come alive within "
                                     f"{self.options.startup_timeout_s:.0f} s")
            self._handle(timeout=remaining, tick=-1, actions=None)

    def _loop(self, publishers) -> bool:
        world = self.world
        episode_start, episode_tick, slowest = time.perf_counter(), world.tick, 0.0
        with EpisodeWriter(self.options.out_dir / EPISODES_FILE) as writer:
            tick_start = self._publish_observations(publishers)
            while not world.finished:
                tick = world.tick
                actions = self._collect_intents(tick)
                if self.stopping:
                    return False
                report = world.apply(actions)
                now = time.perf_counter()
                slowest = max(slowest, now - tick_start)
                if not world.finished:
                    # The next tick starts before this one is logged: agents think meanwhile.
                    tick_start = self._publish_observations(publishers)
                if report.violations:
                    log.error("tick %d broke the world's invariants: %s", tick, report.violations)
                if report.episode_row is not None:
                    writer.write(report.episode_row, now - episode_start, world.tick - episode_tick,
                                 slowest, self.inbox.total_rejected)
                    episode_start, episode_tick, slowest = now, world.tick, 0.0
                if self.on_tick is not None:
                    self.on_tick(world, report)
        return True

    def _publish_observations(self, publishers) -> float:
        """Send every agent its observation of the current tick; returns when the tick began."""
        start = time.perf_counter()
        # In rank order: the first to decide is the first to know.
        for obs in sorted(self.world.observations(), key=lambda o: o.rank):
            publishers[obs.agent].put(encode(obs))
        return start

    def _keep_intent(self, sample: zenoh.Sample) -> None:
        """Zenoh callback: keep an intent; wake the loop once ``wake_at`` intents are kept.

        Intents come one per agent, spread over the tick; the loop needs them all, so it sleeps
        until nearly all are in rather than waking for each one (waking the world eight times a
        tick slowed the negotiation chain it runs beside)."""
        self.intent_samples.append(sample)
        if len(self.intent_samples) >= self.wake_at:
            self.events.put(("intents", None))

    def _collect_intents(self, tick: int) -> list[int | None]:
        """Every live agent's action for ``tick``, or None where none came by the deadline."""
        actions: list[int | None] = [None] * self.config.n_agents
        deadline = time.monotonic() + self.config.tick_deadline_s
        while not self.stopping:
            missing = sum(actions[i] is None for i in self.alive)
            if not missing:
                break
            # Wake when all but one are in, so that only the last one's decoding is left for the
            # moment it comes; then for the last.
            self.wake_at = max(missing - 1, 1)
            if len(self.intent_samples) < self.wake_at:  # checked after setting: no lost wake
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    break
                self._handle(timeout=remaining, tick=tick, actions=actions)
            samples, self.intent_samples = self.intent_samples, []
            for sample in samples:
                self._on_intent(sample, tick, actions)
        self.wake_at = 1
        return actions

    def _handle(self, timeout: float, tick: int, actions: list[int | None] | None) -> None:
        """Handle one event (or none, if ``timeout`` passes first)."""
        try:
            kind, sample = self.events.get(timeout=timeout)
        except queue.Empty:
            return
        if kind == "alive":
            agent = keys.agent_from_key(str(sample.key_expr), self.config.run_id)
            if agent is None or agent >= self.config.n_agents:
                self.inbox.reject("unknown-agent", str(sample.key_expr))
            elif sample.kind == zenoh.SampleKind.PUT:
                self.alive.add(agent)
                log.info("agent %d is alive", agent)
            else:
                self.alive.discard(agent)
                log.warning("agent %d left", agent)

    def _on_intent(self, sample: zenoh.Sample, tick: int, actions: list[int | None] | None) -> None:
        key_agent = keys.agent_from_key(str(sample.key_expr), self.config.run_id)
        intent = self.inbox.decode(sample.payload, Intent, key_agent=key_agent)
        if intent is None:
            return
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
