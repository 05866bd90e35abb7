"""The agent process: one AgentBrain behind a Zenoh session.

Per tick: receive the observation on ``world/obs/<id>``; learn the intents of the visible
higher-ranked neighbours as ``agent.negotiation`` plans it: from the standing query this agent keeps
open on its predecessor's intent key (``agent/<id-1>/intent?since=T;from=<id>``), and, where the
plan needs more, with one ``get`` each on ``agent/<j>/intent?tick=T;from=<id>`` (answers relay what
their senders learned); decide; answer the standing and held queries this tick owes, the next in
rank first, and publish the intent on ``agent/<id>/intent`` for the world. An announced intent
never changes. At each episode's end, checkpoint the Q-tables atomically.

The node is a set of event handlers over one state, each run under the node's lock. Observations,
answers and queries are handled where Zenoh delivers them, on its network thread: the moment the
last awaited intent arrives, the agent decides and answers there, without waking another thread
(that hand-over cost about 50 us a hop; README, "where the time goes"). Nothing there blocks: an
agent waiting for intents is only a :class:`Pending` record. The main thread handles the rest
(liveliness, the world's control messages), the negotiation's time-outs and each episode's end,
whose checkpoint writes a file. Liveliness callbacks only enqueue and never take the lock: Zenoh
has called them holding its own tables lock (eclipse-zenoh/zenoh#1092), and a callback waiting for
ours while we call into Zenoh would deadlock.
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

from agent import checkpoint, negotiation
from agent.brain import AgentBrain
from protocol import keys, trace
from protocol.config import NEGOTIATING_ALGOS, SwarmConfig, priority_rank
from protocol.messages import (
    CONTROL_SHUTDOWN, Answer, Control, Inbox, Intent, Observation, agent_sender, encode,
)
from protocol.runfiles import CHECKPOINT_DIR, stats_path, write_json_atomic
from protocol.transport import (
    EXIT_TRANSPORT, TransportError, TransportSettings, callback, enqueue, open_session,
)

log = logging.getLogger("nnql.agent")

NO_CONSOLIDATION = zenoh.ConsolidationMode.NONE
"""Answers are delivered as they come; Zenoh's default would hold them until the query ends."""

POLL_S = 0.05
"""How often the main thread checks whether it was asked to stop and whether a negotiation ran out
of time (a time-out is noticed up to this late)."""

RESYNC_AFTER = 3
"""Consecutive observations past a gap in the ticks after which an agent follows them."""

MAX_HELD_QUERIES = 4 * 1024
"""Queries for the coming tick held at once; legitimately at most one per other agent."""

EXIT_STOPPED = 130
"""Exit code of an agent stopped by a signal rather than by the world's shutdown."""

AHEAD_TICKS = 2
"""How far past its last decision an agent holds queries and keeps answers: a neighbour that has
decided this tick may ask for, or answer, the next one before this agent decides this one."""

STANDING_QUERY_S = 600.0
"""Lifetime of a standing query; when it ends, the agent opens another after its next decision."""

PEER_WAIT_S = 30.0
"""How long an agent waits at start-up to see every other agent before it acts anyway."""

_NOTHING = negotiation.TickIntents()
"""What an agent knows of a tick nobody answered for (never written to)."""


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


@dataclass
class Pending:
    """An observation whose decision waits for intents: whose (``awaited``), which of them the
    brain decides with (``needed``), whom this agent asked (``asks``), until when, and, once the
    answers are in, the ones it then asked for directly because no answer brought them
    (``missing``)."""

    obs: Observation
    awaited: list[int]
    needed: list[int]
    asks: list[int]
    deadline: float
    missing: list[int] | None = None


class AgentNode:
    """The agent's event handlers over its Zenoh session (see the module docstring)."""

    def __init__(self, options: AgentOptions, session: zenoh.Session,
                 brain: AgentBrain | None = None,
                 on_episode_end: Callable[[AgentBrain, int], None] | None = None) -> None:
        self.options = options
        self.config = options.config
        self.agent = options.agent
        self.sender = agent_sender(self.agent)
        self.session = session
        self.brain = brain or AgentBrain(self.agent, self.config)
        self.on_episode_end = on_episode_end
        self.inbox = Inbox(self.config.run_id, log)
        self.trace = trace.TickTrace.from_env(f"agent-{self.agent}")
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.RLock()
        self.stopping = False
        self.failure: BaseException | None = None
        self.ready = False  # every peer seen (or given up on): observations are handled
        self.early_observations: list = []
        self.pending: Pending | None = None
        self.decided_tick = -1
        self.decided_payload = b""
        self.decided_obs: Observation | None = None
        self.held_queries: list[tuple[int, int, zenoh.Query]] = []  # (tick, asker's rank, query)
        self.standing: dict[int, zenoh.Query] = {}  # asker -> its standing query on this agent
        self.intents: dict[int, negotiation.TickIntents] = {}  # tick -> what was learned of it
        self.predecessor = (self.agent - 1) % self.config.n_agents
        self.stream_open = False
        self.stream_generation = 0
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

    def _guarded(self, handler: Callable, *args) -> Callable:
        """``handler(*args, item)`` as a Zenoh callback: under the lock, and a bug in it stops
        the agent (``run`` raises it) instead of vanishing into Zenoh's thread."""
        def guarded(*item) -> None:
            with self.lock:
                if self.stopping:
                    return
                try:
                    handler(*args, *item)
                except Exception as error:  # noqa: BLE001 - re-raised by run() on the main thread
                    self.failure = error
                    self.stop()
        return guarded

    def run(self) -> None:
        run_id, s = self.config.run_id, self.session
        with (
            s.declare_subscriber(keys.obs_key(run_id, self.agent),
                                 callback(self._guarded(self._on_observation_sample))),
            s.declare_subscriber(keys.control_key(run_id),
                                 enqueue(self.events, "control")),
            s.declare_queryable(keys.intent_key(run_id, self.agent),
                                callback(self._guarded(self._on_query))),
            s.declare_publisher(keys.intent_key(run_id, self.agent), express=True,
                                congestion_control=zenoh.CongestionControl.BLOCK) as publisher,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_AGENT, self.agent)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              enqueue(self.events, "alive"),
                                              history=True),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_WORLD),
                                              enqueue(self.events, "world")),
        ):
            self.publisher = publisher
            try:
                self._wait_for_peers()
                while not self.stopping:
                    try:
                        kind, item = self.events.get(timeout=POLL_S)
                    except queue.Empty:
                        kind, item = None, None
                    with self.lock:
                        if kind is not None:
                            self._dispatch(kind, item)
                        if self.pending is not None and not self.stopping:
                            self._advance()  # a negotiation may have run out of time
            finally:
                with self.lock:
                    self.stopping = True
                    self._drop_held_queries()
                    self._drop_standing_queries()
        if self.failure is not None:
            raise self.failure

    def _wait_for_peers(self) -> None:
        """Wait until every other agent's token is seen, so negotiation reaches all of them;
        then handle the observations that came meanwhile, in order.

        Peers join into a mesh a little after they reach the world; a query sent before that
        would find nobody.
        """
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
            with self.lock:
                self._dispatch(kind, item)
        with self.lock:
            self.ready = True
            early, self.early_observations = self.early_observations, []
            for payload in early:
                self._on_observation(payload)

    def _dispatch(self, kind: str, item) -> None:
        """A main-thread event (under the lock)."""
        if kind == "control":
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
            self.pending = None
            self.brain.learner.forget_pending()
            self.intents = {}
            self._drop_held_queries()

    def _on_alive(self, sample: zenoh.Sample) -> None:
        agent = keys.agent_from_key(str(sample.key_expr), self.config.run_id)
        if agent is None:
            self.inbox.reject("unknown-agent", str(sample.key_expr))
        elif sample.kind == zenoh.SampleKind.PUT:
            self.peers_seen.add(agent)
        else:
            self.peers_seen.discard(agent)
            if agent == self.predecessor:
                self.stream_open = False  # ask its next incarnation afresh
            query = self.standing.pop(agent, None)
            if query is not None:
                query.drop()

    def _on_observation_sample(self, sample: zenoh.Sample) -> None:
        if self.ready:
            self._on_observation(sample.payload)
        else:
            self.early_observations.append(sample.payload)

    def _on_observation(self, payload) -> None:
        """Start a tick: decide at once if no intent is awaited, else ask and wait for them."""
        arrived = self.trace.now()
        obs = self.inbox.decode(payload, Observation)
        if obs is None:
            return
        self.trace.mark(trace.OBS_IN, obs.tick, at=arrived)
        if obs.agent != self.agent:
            self.inbox.reject("wrong-agent", f"observation for agent {obs.agent}")
            return
        if self.pending is not None and obs.tick == self.pending.obs.tick + 1:
            self._decide_pending()  # the world has moved on (this agent stalled): decide now
        if obs.tick <= self.decided_tick:
            self.inbox.reject("stale-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        if self.decided_tick >= 0 and obs.tick != self.decided_tick + 1 and not self._resync(obs):
            self.inbox.reject("future-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        needed = self.brain.neighbours_to_ask(obs)
        awaited, asks = negotiation.plan_for(obs, self.config)
        # An episode's end is decided on the main thread: its checkpoint writes a file.
        decide_here = not obs.episode_end or threading.current_thread() is threading.main_thread()
        if not awaited and decide_here:
            self._decide(obs, {})
            return
        tick, timeout = obs.tick, self.options.negotiation_timeout_s
        got = self._intents_of(tick)
        for j in asks:
            if j not in got.answered and not (j == self.predecessor and self.stream_open):
                self._ask(j, tick, timeout)
        self.pending = Pending(obs, awaited, needed, asks, time.monotonic() + timeout)
        if obs.episode_end:
            self.events.put(("wake", None))  # for the main thread to decide it
        else:
            self.brain.prepare(obs)  # while the answers are on their way
            self._advance()

    def _intents_of(self, tick: int) -> negotiation.TickIntents:
        """What this agent has learned of ``tick``'s intents (kept from now on)."""
        got = self.intents.get(tick)
        if got is None:
            got = self.intents[tick] = negotiation.TickIntents()
        return got

    def _advance(self) -> None:
        """Move the pending negotiation on: once every asked neighbour answered (or time ran
        out), ask directly for any awaited intent that no answer brought; once those are in
        too (or time ran out), decide. Unanswered neighbours are left out."""
        p = self.pending
        got = self._intents_of(p.obs.tick)
        remaining = p.deadline - time.monotonic()
        if p.missing is None:
            if remaining > 0 and not all(j in got.answered for j in p.asks):
                return
            if self.predecessor in p.asks and self.predecessor not in got.answered:
                self.stream_open = False  # it did not answer in time: open a fresh one
            p.missing = [j for j in p.awaited if j not in got.actions]
            if p.missing and remaining > 0:
                for j in p.missing:
                    self._ask(j, p.obs.tick, remaining)
                return
        elif remaining > 0 and not all(j in got.actions for j in p.missing):
            return
        self._decide_pending()

    def _decide_pending(self) -> None:
        p, self.pending = self.pending, None
        known = self.intents.get(p.obs.tick, _NOTHING).actions
        self._decide(p.obs, {j: known[j] for j in p.needed if j in known})

    def _decide(self, obs: Observation, answers: dict[int, int]) -> None:
        """Decide ``obs`` with the ``answers`` of the neighbours the brain waits for; answer
        for it, relaying every intent learned for the tick; checkpoint at an episode's end;
        tell the world."""
        self.trace.mark(trace.DECIDE, obs.tick)
        action = self.brain.act(obs, answers)
        self.trace.mark(trace.ACTED, obs.tick)
        known = self.intents.get(obs.tick, _NOTHING).actions
        answer = Answer(self.config.run_id, obs.tick, self.sender, self.agent, obs.episode, action,
                        tuple(sorted(known.items())))
        self.decided_tick, self.decided_obs, self.decided_payload = obs.tick, obs, encode(answer)
        self.trace.mark(trace.ENCODED, obs.tick)
        self.intents = {t: got for t, got in self.intents.items() if t > obs.tick}
        self._answer_standing_queries()
        self.trace.mark(trace.ANSWERED, obs.tick)
        self._answer_held_queries()
        if obs.episode_end:  # saved before the world hears of the decision: nothing to lose
            checkpoint.save(self.checkpoint_file, self.brain, obs.episode)
        intent = encode(Intent(answer.run, answer.tick, answer.sender, self.agent, obs.episode,
                               action, self.brain.learned))
        self.trace.mark(trace.INTENT_SENT, obs.tick)
        self.publisher.put(intent)
        if obs.episode_end and self.on_episode_end is not None:
            # After the intent, so that the world need not wait for it; the tables stay put
            # meanwhile (the next decision needs the lock this holds).
            self.on_episode_end(self.brain, obs.episode)
        if not self.stream_open:
            self._open_stream(obs.tick + 1)

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

    def _answer_handler(self, sender: int, generation: int | None = None):
        """The handler of a query to ``sender``: its replies are handled as answers and, for a
        standing query, its end closes the stream."""
        end = None if generation is None else self._guarded(self._on_stream_end, generation)
        return callback(self._guarded(self._on_answer, sender), end)

    def _on_stream_end(self, generation: int) -> None:
        if generation == self.stream_generation:
            self.stream_open = False

    def _ask(self, neighbour: int, tick: int, timeout_s: float) -> None:
        """Ask one neighbour for its intent at ``tick``; its answer comes to ``_on_answer``."""
        selector = (f"{keys.intent_key(self.config.run_id, neighbour)}"
                    f"?{keys.intent_query_params(tick, self.agent)}")
        self.session.get(selector, self._answer_handler(neighbour), express=True,
                         consolidation=NO_CONSOLIDATION, timeout=timeout_s)

    def _open_stream(self, since: int) -> None:
        """Open the standing query on the predecessor's intent key (nnQL only)."""
        if (self.config.algo not in NEGOTIATING_ALGOS or self.config.n_agents < 2
                or self.predecessor not in self.peers_seen or since >= keys.MAX_TICK):
            return
        self.stream_generation += 1
        selector = (f"{keys.intent_key(self.config.run_id, self.predecessor)}"
                    f"?{keys.standing_query_params(since, self.agent)}")
        self.session.get(selector, self._answer_handler(self.predecessor, self.stream_generation),
                         express=True, consolidation=NO_CONSOLIDATION, timeout=STANDING_QUERY_S)
        self.stream_open = True

    def _on_answer(self, sender: int, reply: zenoh.Reply) -> None:
        """Keep an answer for the coming ticks, and move the negotiation on if it waits for it;
        answers for decided ticks are of no more use (a standing query also brings those this
        agent did not need)."""
        sample = reply.ok
        if sample is None:
            return  # the query's end: a timeout, or a neighbour that is gone
        arrived = self.trace.now()
        answer = self.inbox.decode(sample.payload, Answer, key_agent=sender)
        if answer is None or answer.tick <= self.decided_tick:
            return
        self.trace.mark(trace.ANSWER_IN, answer.tick, at=arrived)
        if self.decided_tick >= 0 and answer.tick > self.decided_tick + AHEAD_TICKS:
            self.inbox.reject("future-tick", f"answer for tick {answer.tick}, "
                                             f"decided {self.decided_tick}")
            return
        got = self._intents_of(answer.tick)
        if not got.add(sender, answer.action, answer.relayed, self.agent):
            self.inbox.reject("conflicting-relay", f"agent {sender} at tick {answer.tick}")
        while len(self.intents) > AHEAD_TICKS + 1:  # a flood of forged ticks stays bounded
            del self.intents[min(self.intents)]
        p = self.pending
        if p is not None and p.obs.tick == answer.tick and not p.obs.episode_end:
            self._advance()

    def _on_query(self, query: zenoh.Query) -> None:
        tick = keys.parse_intent_query(query.parameters)
        since = keys.parse_standing_since(query.parameters) if tick is None else None
        if since is not None:
            self._on_standing_query(query, since, keys.parse_intent_asker(query.parameters))
        elif tick is None:
            self.inbox.reject("bad-query", str(query.selector))
            query.reply_err(b"bad query: expected ?tick=T or ?since=T;from=A")
            query.drop()
        elif tick <= self.decided_tick:
            self._answer(tick, query)
        elif self.decided_tick >= 0 and tick > self.decided_tick + AHEAD_TICKS:
            self.inbox.reject("future-query", f"tick {tick}, decided {self.decided_tick}")
            query.reply_err(b"future tick")
            query.drop()
        elif len(self.held_queries) >= MAX_HELD_QUERIES:
            self.inbox.reject("query-flood", f"{len(self.held_queries)} queries held")
            query.reply_err(b"too many queries")
            query.drop()
        else:
            asker = keys.parse_intent_asker(query.parameters)
            order = self.config.n_agents if asker is None else priority_rank(
                asker, tick, self.config.n_agents)
            self.held_queries.append((tick, order, query))

    def _on_standing_query(self, query: zenoh.Query, since: int, asker: int | None) -> None:
        """Keep a neighbour's standing query (one per asker: a newer one replaces it), and
        answer it at once if the tick it starts from is already decided."""
        if asker is None or asker == self.agent or asker >= self.config.n_agents:
            self.inbox.reject("bad-query", str(query.selector))
            query.reply_err(b"bad standing query: expected ?since=T;from=<another agent>")
            query.drop()
            return
        old = self.standing.pop(asker, None)
        if old is not None:
            old.drop()
        self.standing[asker] = query
        if since <= self.decided_tick and self.decided_obs is not None:
            self._answer_standing(asker, query)

    def _answer_standing_queries(self) -> None:
        """Answer the standing queries owed at the decided tick, the next in rank first."""
        n = self.config.n_agents
        for asker in sorted(self.standing, key=lambda a: priority_rank(a, self.decided_tick, n)):
            self._answer_standing(asker, self.standing[asker])

    def _answer_standing(self, asker: int, query: zenoh.Query) -> None:
        if not negotiation.answers_standing(self.decided_obs, asker, self.config):
            return
        try:
            query.reply(query.key_expr, self.decided_payload)
        except zenoh.ZError as error:  # the asker is gone; it opens a new one if it comes back
            log.info("standing query of agent %d ended: %s", asker, error)
            self.standing.pop(asker, None)
            query.drop()

    def _answer_held_queries(self) -> None:
        """Answer what was asked for the decided tick, the next in rank first: its decision
        is the one the rest of the chain waits for."""
        due = sorted((h for h in self.held_queries if h[0] <= self.decided_tick),
                     key=lambda h: h[1])
        self.held_queries = [h for h in self.held_queries if h[0] > self.decided_tick]
        for tick, _, query in due:
            self._answer(tick, query)

    def _answer(self, tick: int, query: zenoh.Query) -> None:
        if tick == self.decided_tick:
            query.reply(query.key_expr, self.decided_payload)
        else:
            self.inbox.reject("stale-query", f"tick {tick}, decided {self.decided_tick}")
            query.reply_err(b"stale tick")
        query.drop()

    def _drop_held_queries(self) -> None:
        for _, _, query in self.held_queries:
            query.drop()
        self.held_queries = []

    def _drop_standing_queries(self) -> None:
        for query in self.standing.values():
            query.drop()
        self.standing = {}

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

    ``on_episode_end(brain, episode)`` runs after each episode's checkpoint and intent (e.g. Rerun
    heat maps).
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
    node.trace.save()
    write_json_atomic(stats_path(options.out_dir, f"agent-{options.agent}"), node.stats())
    if node.inbox.total_rejected:
        log.warning("rejected %d messages: %s", node.inbox.total_rejected,
                    dict(node.inbox.rejections))
    return 0 if node.shutdown else EXIT_STOPPED
