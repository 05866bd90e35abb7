"""The agent process: ``agent.agent_machine.AgentMachine`` over a Zenoh session.

The machine decides everything (what to ask, when to answer, when to decide); this adapter
feeds it what Zenoh delivers, with the time, and carries out its effects: publish the intent on
``agent/<id>/intent``, ask a neighbour's intent key (``session.get``), reply to a query on its
own intent key, finish a query, write the checkpoint, log.

Threads, in three sentences. Every input reaches the machine under the node's one lock, and its
effects are carried out right there, in order, before the lock is let go (a checkpoint is
written before the intent that follows it is published). Observations, replies and queries are
handled on the thread Zenoh calls back on (its receiving thread, ``transport.runtime``), so the
last awaited intent is acted on without waking another thread, while liveliness and control
messages and the ends of asks are only queued there, because Zenoh calls those callbacks holding
a lock of its own (eclipse-zenoh/zenoh#1092: when a peer dies, Zenoh ends the asks on it under
that lock while the main thread, holding the node's, ends that peer's standing query, and one
waited for the other forever). The main thread handles that queue and the machine's timers,
sleeping on the queue until the next timer is due, at most ``transport.adapter.POLL_S``.

A session that hears no other agent before the run begins (``rejoin_deaf_s``) is closed and
another opened, :data:`REJOINS` times at most (:func:`run_agent`).
"""

import logging
import queue
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable

import zenoh

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.agent_machine import WORLD_WAIT_S, AgentMachine
from nnql_swarm.agent.restore import start_brain
from nnql_swarm.protocol import trace
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import (
    Ask, Checkpoint, EndQuery, EpisodeEnded, Log, Reply, ReplyError, SendIntent, Stopped,
)
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR, stats_path, write_json_atomic
from nnql_swarm.transport.adapter import ProtocolAdapter
from nnql_swarm.transport.callbacks import callback, enqueue
from nnql_swarm.transport.runtime import declare_lockstep_publisher
from nnql_swarm.transport.slotfile import SlotFile
from nnql_swarm.transport.settings import (
    EXIT_NO_WORLD, EXIT_TRANSPORT, TransportSettings, run_in_session,
)

log = logging.getLogger("nnql.agent")

NO_CONSOLIDATION = zenoh.ConsolidationMode.NONE
"""Answers are delivered as they come; Zenoh's default would hold them until the query ends."""

EXIT_STOPPED = 130
"""Exit code of an agent stopped by a signal rather than by the world's shutdown."""

_PUT = zenoh.SampleKind.PUT

REJOINS = 2
"""How many times an agent whose session heard no other agent opens another before it keeps the
last one (``TransportSettings.rejoin_deaf_s``)."""


@dataclass(frozen=True)
class AgentOptions:
    """How one agent process runs."""

    agent: int
    config: SwarmConfig
    transport: TransportSettings
    out_dir: Path
    resume: bool = False
    resume_episode: int | None = None  # the checkpoint's version to load (None: the newest)
    world_wait_s: float = WORLD_WAIT_S  # how long a world that left may stay away

    @property
    def negotiation_timeout_s(self) -> float:
        return self.config.tick_deadline_s / 2


class AgentNode(ProtocolAdapter):
    """The machine's adapter to one Zenoh session (see the module docstring)."""

    protocol: AgentMachine

    def __init__(self, options: AgentOptions, session: zenoh.Session,
                 brain: AgentBrain | None = None,
                 on_episode_end: Callable[[AgentBrain, int], None] | None = None) -> None:
        self.options = options
        self.config = options.config
        self.agent = options.agent
        self.session = session
        self.on_episode_end = on_episode_end
        self.checkpoint_file = agent_checkpoint.checkpoint_path(options.out_dir / CHECKPOINT_DIR,
                                                          self.agent)
        self._checkpoint_slots = SlotFile(self.checkpoint_file)  # written by this process only
        brain, self.resumed = start_brain(self.agent, self.config, self.checkpoint_file,
                                          options.resume, brain, options.resume_episode)
        if self.resumed is not None:
            log.warning("resumed from %s (episode %d, tables %s)", self.checkpoint_file,
                        self.resumed["episode"], self.resumed["fingerprint"])
        self.brain = brain
        self.trace = trace.TickTrace.from_env(f"agent-{self.agent}")
        self.protocol = AgentMachine(self.agent, self.config, brain, time.monotonic(),
                                     options.negotiation_timeout_s, self.trace,
                                     options.world_wait_s, options.transport.rejoin_deaf_s)
        self.rejoin = False  # its session heard no other agent: open another (run_agent)
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.RLock()
        self.stopping = False
        self.failure: BaseException | None = None
        self.handler_cpu = {}
        self.publisher: zenoh.Publisher | None = None
        self.queries: dict[int, zenoh.Query] = {}
        self.next_query = 0
        run_id = self.config.run_id
        self.intent_keys = [keys.intent_key(run_id, j) for j in range(self.config.n_agents)]
        self._do = {
            SendIntent: self._send_intent, Ask: self._ask, Reply: self._reply,
            ReplyError: self._reply_error, EndQuery: self._end_query,
            Checkpoint: self._checkpoint, EpisodeEnded: self._episode_ended, Log: self._log,
            Stopped: self._stopped,
        }

    @property
    def shutdown(self) -> bool:
        return self.protocol.shutdown

    def stop(self) -> None:
        self.stopping = True
        self.events.put(("stop", None))

    # Inputs, on whichever thread they arrive, one at a time under the lock.

    def _on_observation(self, sample: zenoh.Sample) -> None:
        self.feed(self.protocol.on_observation, sample.payload)

    def _on_query(self, query: zenoh.Query) -> None:
        with self.lock:
            if self.stopping:
                query.drop()
                return
            number = self.next_query
            self.next_query += 1
            self.queries[number] = query
            self.feed(self.protocol.on_query, number, query.parameters)

    def _replies(self, ask: int) -> zenoh.handlers.Callback:
        """The handler of one ask: its replies are answers, its end ends the ask."""
        protocol = self.protocol

        def on_reply(reply: zenoh.Reply) -> None:
            sample = reply.ok
            if sample is not None:
                self.feed(protocol.on_answer, ask, sample.payload)
            else:  # an error reply: the neighbour cannot answer that tick
                self.feed(protocol.on_refusal, ask)

        return callback(on_reply, lambda: self.events.put(("ask-end", ask)))

    # Effects, in order.

    def _send_intent(self, effect: SendIntent) -> None:
        tick = effect.intent.tick
        self.trace.mark(trace.ANSWERED, tick)
        self.trace.mark(trace.INTENT_SENT, tick)
        assert self.publisher is not None, "intents are sent only while the node runs"
        self.publisher.put(effect.payload)

    def _ask(self, effect: Ask) -> None:
        self.session.get(f"{self.intent_keys[effect.agent]}?{effect.parameters}",
                         self._replies(effect.ask), consolidation=NO_CONSOLIDATION, timeout=effect.timeout_s)

    def _reply(self, effect: Reply) -> None:
        query = self.queries.get(effect.query)
        if query is None:
            return
        try:
            query.reply(query.key_expr, effect.payload)
        except zenoh.ZError as error:  # the asker is gone
            log.info("query %d ended: %s", effect.query, error)
            self.perform(self.protocol.on_reply_failed(effect.query, time.monotonic()))

    def _reply_error(self, effect: ReplyError) -> None:
        query = self.queries.get(effect.query)
        if query is not None:
            query.reply_err(effect.message)

    def _end_query(self, effect: EndQuery) -> None:
        query = self.queries.pop(effect.query, None)
        if query is not None:
            query.drop()

    def _checkpoint(self, effect: Checkpoint) -> None:
        agent_checkpoint.save(self._checkpoint_slots, self.brain, effect.episode)

    def _episode_ended(self, effect: EpisodeEnded) -> None:
        if self.on_episode_end is not None:
            self.on_episode_end(self.brain, effect.episode)

    def _log(self, effect: Log) -> None:
        log.log(effect.level, effect.message, *effect.args)

    def _stopped(self, effect: Stopped) -> None:
        self.stopping = True
        self.rejoin = effect.rejoin
        self.events.put(("stop", None))

    # The main thread.

    def run(self) -> None:
        run_id, s, protocol = self.config.run_id, self.session, self.protocol
        with (
            s.declare_subscriber(keys.obs_key(run_id, self.agent), callback(self._on_observation)),
            s.declare_subscriber(keys.control_key(run_id), enqueue(self.events, "control")),
            s.declare_queryable(self.intent_keys[self.agent], callback(self._on_query)),
            declare_lockstep_publisher(s, self.intent_keys[self.agent]) as publisher,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_AGENT, self.agent)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              enqueue(self.events, "alive"), history=True),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_WORLD),
                                              enqueue(self.events, "world")),
        ):
            self.publisher = publisher
            try:
                while not self.stopping:
                    kind, item = self.next_event()
                    if kind == "control":
                        self.feed(protocol.on_control, item.payload)
                    elif kind == "alive":
                        self.feed(protocol.on_liveliness, str(item.key_expr), item.kind == _PUT)
                    elif kind == "world":
                        self.feed(protocol.on_world, item.kind == _PUT)
                    elif kind == "ask-end":
                        self.feed(protocol.on_ask_end, item)
                    self.fire_timer_if_due()
            finally:
                with self.lock:
                    self.stopping = True
                    self.perform(protocol.stop(time.monotonic()))
                    for query in self.queries.values():
                        query.drop()
                    self.queries = {}
        if self.failure is not None:
            raise self.failure

    def stats(self) -> dict:
        return {**self.protocol.stats(), "resumed": self.resumed,
                "decides": self.brain.decides,
                "handler_cpu": self.handler_cpu_stats()}


def run_agent(options: AgentOptions, brain: AgentBrain | None = None,
              on_episode_end: Callable[[AgentBrain, int], None] | None = None) -> int:
    """Entry point of an agent process; returns its exit code.

    ``on_episode_end(brain, episode)`` runs after each episode's checkpoint and intent (e.g. Rerun
    heat maps).
    """
    for rejoins in range(REJOINS + 1):
        if rejoins == REJOINS:  # the last session: kept, deaf or not
            options = replace(options, transport=replace(options.transport, rejoin_deaf_s=0.0))
        ran = run_in_session(options.transport, lambda session: AgentNode(
            options, session, brain, on_episode_end))
        if ran is None:
            return EXIT_TRANSPORT
        node = ran[0]
        if not node.rejoin:
            break
        brain = node.brain  # as it was: nothing ran yet
    node.trace.save()
    write_json_atomic(stats_path(options.out_dir, f"agent-{options.agent}"), node.stats())
    inbox = node.protocol.inbox
    if inbox.total_rejected:
        log.warning("rejected %d messages: %s", inbox.total_rejected, dict(inbox.rejections))
    if node.protocol.world_lost:
        return EXIT_NO_WORLD
    return 0 if node.shutdown else EXIT_STOPPED
