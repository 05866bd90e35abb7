"""The agent process: one AgentBrain behind a Zenoh session.

Per tick: receive the observation on ``world/obs/<id>``; ask the visible higher-ranked neighbours
for their intent with one concurrent ``get`` each on ``agent/<j>/intent?tick=T``; decide; publish
the intent on ``agent/<id>/intent`` and answer every query for it (queries that arrived early are
held until then, and an announced intent never changes). At each episode's end, checkpoint the
Q-tables atomically. Zenoh callbacks only hand events to a queue; all work is on the main thread.
"""

import logging
import queue
import signal
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh

from agent import checkpoint
from agent.brain import AgentBrain
from protocol import keys
from protocol.config import SwarmConfig
from protocol.messages import (
    CONTROL_SHUTDOWN, Control, Inbox, Intent, Observation, agent_sender, encode,
)
from protocol.runfiles import CHECKPOINT_DIR, stats_path, write_json_atomic
from protocol.transport import EXIT_TRANSPORT, TransportError, TransportSettings, open_session

log = logging.getLogger("nnql.agent")

POLL_S = 0.2
"""How often a waiting agent checks whether it was asked to stop."""

RESYNC_AFTER = 3
"""Consecutive observations past a gap in the ticks after which an agent follows them."""

MAX_HELD_QUERIES = 4 * 1024
"""Queries for the coming tick held at once; legitimately at most one per other agent."""

EXIT_STOPPED = 130
"""Exit code of an agent stopped by a signal rather than by the world's shutdown."""

PEER_WAIT_S = 30.0
"""How long an agent waits at start-up to see every other agent before it acts anyway."""


@dataclass(frozen=True)
class AgentOptions:
    """How one agent process runs."""

    agent: int
    config: SwarmConfig
    transport: TransportSettings
    out_dir: Path
    resume: bool = False

    @property
    def negotiation_timeout_s(self) -> float:
        return self.config.tick_deadline_s / 2


class AgentNode:
    """The agent's event loop over its Zenoh session."""

    def __init__(self, options: AgentOptions, session: zenoh.Session,
                 brain: AgentBrain | None = None,
                 on_episode_end: Callable[[AgentBrain, int], None] | None = None) -> None:
        self.options = options
        self.config = options.config
        self.agent = options.agent
        self.session = session
        self.brain = brain or AgentBrain(self.agent, self.config)
        self.on_episode_end = on_episode_end
        self.inbox = Inbox(self.config.run_id, log)
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.stopping = False
        self.decided_tick = -1
        self.decided_payload = b""
        self.held_queries: list[tuple[int, zenoh.Query]] = []
        self.peers_seen: set[int] = set()
        self.gap_tick, self.gap_run = -1, 0
        self.shutdown = False
        self.resumed: dict | None = None
        self.checkpoint_file = checkpoint.checkpoint_path(options.out_dir / CHECKPOINT_DIR, self.agent)
        if options.resume and self.checkpoint_file.exists():
            episode = checkpoint.load(self.checkpoint_file, self.brain)
            self.resumed = {"episode": episode, "fingerprint": checkpoint.fingerprint(self.brain)}
            log.warning("resumed from %s (episode %d, tables %s)",
                        self.checkpoint_file, episode, self.resumed["fingerprint"])

    def stop(self) -> None:
        self.stopping = True
        self.events.put(("stop", None))

    def run(self) -> None:
        run_id, s = self.config.run_id, self.session
        with (
            s.declare_subscriber(keys.obs_key(run_id, self.agent),
                                 lambda sample: self.events.put(("obs", sample))),
            s.declare_subscriber(keys.control_key(run_id),
                                 lambda sample: self.events.put(("control", sample))),
            s.declare_queryable(keys.intent_key(run_id, self.agent),
                                lambda query: self.events.put(("query", query))),
            s.declare_publisher(keys.intent_key(run_id, self.agent), express=True,
                                congestion_control=zenoh.CongestionControl.BLOCK) as publisher,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_AGENT, self.agent)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              lambda sample: self.events.put(("alive", sample)),
                                              history=True),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_WORLD),
                                              lambda sample: self.events.put(("world", sample))),
        ):
            self.publisher = publisher
            for kind, item in self._wait_for_peers():
                self._dispatch(kind, item)
            while not self.stopping:
                try:
                    kind, item = self.events.get(timeout=POLL_S)
                except queue.Empty:
                    continue
                self._dispatch(kind, item)
            self._drop_held_queries()

    def _wait_for_peers(self) -> list:
        """Wait until every other agent's token is seen, so negotiation reaches all of them.

        Peers join into a mesh a little after they reach the world; a query sent before that
        would find nobody. Events that arrive meanwhile are kept and returned, in order.
        """
        backlog = []
        others = self.config.n_agents - 1
        deadline = time.monotonic() + PEER_WAIT_S
        while len(self.peers_seen - {self.agent}) < others and not self.stopping:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                log.warning("only saw agents %s; negotiating with whoever answers",
                            sorted(self.peers_seen))
                break
            try:
                kind, item = self.events.get(timeout=min(remaining, POLL_S))
            except queue.Empty:
                continue
            if kind == "alive":
                self._on_alive(item)
            else:
                backlog.append((kind, item))
        return backlog

    def _dispatch(self, kind: str, item) -> None:
        if kind == "obs":
            self._on_observation(item.payload)
        elif kind == "query":
            self._on_query(item)
        elif kind == "control":
            self._on_control(item.payload)
        elif kind == "alive":
            self._on_alive(item)
        elif kind == "world":
            self._on_world_alive(item)

    def _on_world_alive(self, sample: zenoh.Sample) -> None:
        """A world that leaves may come back (``--resume``) with its own clock: start afresh."""
        if sample.kind == zenoh.SampleKind.DELETE:
            log.info("the world left; waiting for it to come back")
            self.decided_tick = -1
            self.brain.learner.forget_pending()
            self._drop_held_queries()

    def _on_alive(self, sample: zenoh.Sample) -> None:
        agent = keys.agent_from_key(str(sample.key_expr), self.config.run_id)
        if agent is None:
            self.inbox.reject("unknown-agent", str(sample.key_expr))
        elif sample.kind == zenoh.SampleKind.PUT:
            self.peers_seen.add(agent)
        else:
            self.peers_seen.discard(agent)

    def _on_observation(self, payload) -> None:
        obs = self.inbox.decode(payload, Observation)
        if obs is None:
            return
        if obs.agent != self.agent:
            self.inbox.reject("wrong-agent", f"observation for agent {obs.agent}")
            return
        if obs.tick <= self.decided_tick:
            self.inbox.reject("stale-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        if self.decided_tick >= 0 and obs.tick != self.decided_tick + 1 and not self._resync(obs):
            self.inbox.reject("future-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        answers = self._ask(self.brain.neighbours_to_ask(obs), obs.tick)
        action = self.brain.act(obs, answers)
        intent = Intent(run=self.config.run_id, tick=obs.tick, sender=agent_sender(self.agent),
                        agent=self.agent, episode=obs.episode, action=action)
        self.decided_tick, self.decided_payload = obs.tick, encode(intent)
        if obs.episode_end:
            checkpoint.save(self.checkpoint_file, self.brain, obs.episode)
            if self.on_episode_end is not None:
                self.on_episode_end(self.brain, obs.episode)
        self.publisher.put(self.decided_payload)
        self._answer_held_queries()

    def _resync(self, obs: Observation) -> bool:
        """After a gap (an observation lost on the way), follow the clock again once
        ``RESYNC_AFTER`` observations in a row continue one another; a lone message with a far
        tick (forged, or stale from another run of the world) never moves this agent's clock."""
        if obs.tick == self.gap_tick + 1:
            self.gap_run += 1
        else:
            self.gap_run = 1
        self.gap_tick = obs.tick
        if self.gap_run < RESYNC_AFTER:
            return False
        log.warning("lost observations before tick %d; following the world's clock again",
                    obs.tick)
        self.gap_run = 0
        return True

    def _ask(self, neighbours: list[int], tick: int) -> dict[int, int]:
        """One concurrent query per neighbour; unanswered neighbours are left out."""
        run_id = self.config.run_id
        pending = [
            (j, self.session.get(
                f"{keys.intent_key(run_id, j)}?{keys.intent_query_params(tick)}",
                timeout=self.options.negotiation_timeout_s,
                express=True,
            ))
            for j in neighbours
        ]
        answers = {}
        for j, replies in pending:
            for reply in replies:
                if not reply.ok:
                    continue
                intent = self.inbox.decode(reply.ok.payload, Intent, key_agent=j)
                if intent is None:
                    continue
                if intent.tick != tick:
                    self.inbox.reject("stale-tick", f"answer for tick {intent.tick}, asked {tick}")
                    continue
                answers[j] = intent.action
        return answers

    def _on_query(self, query: zenoh.Query) -> None:
        tick = keys.parse_intent_query(query.parameters)
        if tick is None:
            self.inbox.reject("bad-query", str(query.selector))
            query.reply_err(b"bad query: expected ?tick=T")
            query.drop()
        elif tick <= self.decided_tick:
            self._answer(tick, query)
        elif self.decided_tick >= 0 and tick > self.decided_tick + 1:
            self.inbox.reject("future-query", f"tick {tick}, decided {self.decided_tick}")
            query.reply_err(b"future tick")
            query.drop()
        elif len(self.held_queries) >= MAX_HELD_QUERIES:
            self.inbox.reject("query-flood", f"{len(self.held_queries)} queries held")
            query.reply_err(b"too many queries")
            query.drop()
        else:
            self.held_queries.append((tick, query))

    def _answer_held_queries(self) -> None:
        still_early = []
        for tick, query in self.held_queries:
            if tick <= self.decided_tick:
                self._answer(tick, query)
            else:
                still_early.append((tick, query))
        self.held_queries = still_early

    def _answer(self, tick: int, query: zenoh.Query) -> None:
        if tick == self.decided_tick:
            query.reply(query.key_expr, self.decided_payload, express=True)
        else:
            self.inbox.reject("stale-query", f"tick {tick}, decided {self.decided_tick}")
            query.reply_err(b"stale tick")
        query.drop()

    def _drop_held_queries(self) -> None:
        for _, query in self.held_queries:
            query.drop()
        self.held_queries = []

    def _on_control(self, payload) -> None:
        control = self.inbox.decode(payload, Control)
        if control is not None and control.command == CONTROL_SHUTDOWN:
            log.info("shutdown from the world")
            self.shutdown = self.stopping = True

    def stats(self) -> dict:
        return {
            "agent": self.agent, "decided_tick": self.decided_tick, "resumed": self.resumed,
            "accepted": self.inbox.accepted, "rejected": dict(self.inbox.rejections),
            "shutdown_by_world": self.shutdown,
        }


def run_agent(options: AgentOptions, brain: AgentBrain | None = None,
              on_episode_end: Callable[[AgentBrain, int], None] | None = None) -> int:
    """Entry point of an agent process; returns its exit code.

    ``on_episode_end(brain, episode)`` runs after each episode's checkpoint (e.g. Rerun heat maps).
    """
    try:
        session = open_session(options.transport)
    except TransportError as error:
        log.error("%s", error)
        return EXIT_TRANSPORT
    with session:
        node = AgentNode(options, session, brain, on_episode_end)
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, lambda *_: node.stop())
        node.run()
    write_json_atomic(stats_path(options.out_dir, f"agent-{options.agent}"), node.stats())
    if node.inbox.total_rejected:
        log.warning("rejected %d messages: %s", node.inbox.total_rejected,
                    dict(node.inbox.rejections))
    return 0 if node.shutdown else EXIT_STOPPED
