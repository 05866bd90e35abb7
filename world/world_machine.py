"""The world's side of the swarm protocol, pure: the lockstep clock as inputs in, effects out.

No sockets, no threads, no clock reads, no files: every input carries its time ``now`` and
returns the effects it causes (``protocol.effects``), in order; :meth:`WorldMachine.timer` is
when it next wants :meth:`WorldMachine.on_timer`. ``world.world_node`` runs it over Zenoh, ``sim``
over a simulated network in virtual time.

Theory of operation. The machine is in one :class:`Phase` at a time, moved only by
:data:`TRANSITIONS` (``protocol.phase_machine``):

- ``STARTING``: it waits for every agent's liveliness token (at most ``startup_timeout_s``; then
  it is ``DONE``, the run failed).
- ``TICK_OPEN``: it has sent every agent its observation of the tick (but the settled ones:
  ``world.engine``), in rank order (the first to decide first), and collects intents until every
  live agent that is not settled (parked on its goal since an earlier tick, where that takes it
  out of the negotiation) has answered or the tick deadline passes (a missing intent counts as
  STAY and as a missed intent; a settled agent stays, and its intent, should one come with a
  learning record, is taken too). Then it applies the tick with ``world.engine``, sends the next
  observations at once, and reports the tick (:class:`~protocol.effects.TickClosed`) and, at an
  episode's end, its row (:class:`~protocol.effects.WriteRow`). A dead agent costs nothing, a
  stalled one at most the deadline. A world that every agent has left (dead, told to stop by a
  forged shutdown, cut off for longer than Zenoh's lease) plays on without them for at most
  ``startup_timeout_s``, as long as it waits for them at the start; if none comes back by then
  it is ``DONE``, the run failed, instead of ticking alone at a deadline a tick.
- ``CLOSING``: the run is complete; it tells its agents to stop until every live one has left.
- ``DONE``: inputs do nothing.

A world started at ``first_episode`` / ``first_tick`` continues a run (``--resume``); one started
after the last episode is ``CLOSING`` from the start, and only tells the agents still running to
stop. Where the agents share one table, an agent that comes back after it left, and every agent
of a resumed world, is sent the world's whole table (``SwarmWorld.resync``) from its first
intent on (by then it surely hears its observations): its copy may be an older checkpoint's.
Until that intent came it is never settled. Each learning record is checked against the
transition the world saw its sender make (``world.records``), as soon as every intent the sender
may have decided with is in, or when the tick closes: one that is not its sender's own
(``forged-record``) is refused, and so are that agent's later records (``barred-record``) until
its liveliness token comes back; one without the sender's decision of the tick before to check
it against (``unchecked-record``) is refused too. Its intent counts either way.
"""

import enum
import logging

import numpy as np

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.actions import STAY
from nnql_swarm.protocol.config import START_S_PER_AGENT, SwarmConfig
from nnql_swarm.protocol.effects import Finished, Log, SendControl, SendObservations, TickClosed, WriteRow
from nnql_swarm.protocol.inbox import Inbox
from nnql_swarm.protocol.messages import CONTROL_SHUTDOWN, WORLD_SENDER, Control, Intent, encode
from nnql_swarm.protocol.phase_machine import EffectLog, Machine, Named, an_input
from nnql_swarm.protocol.trace import CLOSE, TickTrace
from nnql_swarm.world.engine import SwarmWorld
from nnql_swarm.world.records import BARRED, FORGED, UNCHECKED, Decision, RecordCheck, decides

STARTUP_TIMEOUT_S = 60.0
"""How long the world waits at least for every agent to come alive before it gives up."""


def startup_timeout(n_agents: int) -> float:
    """How long a world of ``n_agents`` waits for them all to come alive."""
    return max(STARTUP_TIMEOUT_S, START_S_PER_AGENT * n_agents)

SHUTDOWN_TRIES = 10
SHUTDOWN_REPEAT_S = 0.2
"""A world that completed its run tells its agents to stop up to :data:`SHUTDOWN_TRIES` times,
this far apart, until every live one has left: a shutdown lost on the way would leave an agent
waiting for a world that never comes back. Tries, not a time limit: a world stalled meanwhile
still makes them all."""
SHUTDOWN_QUIET_S = 0.1
"""With no live agent left, the world still waits this long after the last liveliness change
before it ends: a world that was stalled handles what queued meanwhile all at once, and an
agent that came up in the meantime is told too."""

LATE_LOG_FIRST = 3
LATE_LOG_EVERY = 100
"""A tick closed by its deadline without a live agent's intent is logged (which agents) for the
first :data:`LATE_LOG_FIRST` such ticks, then every :data:`LATE_LOG_EVERY`-th: a run held to its
deadline says why, and a long partition does not flood the log."""

_NO_TRACE = TickTrace("world", None)


class Phase(Named):
    """Where the world is in its run (see the module docstring)."""

    STARTING = "waiting for every agent to come alive"
    TICK_OPEN = "collecting the open tick's intents"
    CLOSING = "the run complete: telling the agents to leave"
    DONE = "done"


class Event(Named):
    """What moves the world from one phase to another."""

    STARTED = "every agent alive: the first tick opens"
    TICK_CLOSED = "a tick applied: the next one opens"
    COMPLETE = "the run's last tick applied, or nothing left to play"
    FINISH = "the end: the agents left, time ran out, or the process is stopping"


TRANSITIONS: dict[tuple[enum.Enum, enum.Enum], enum.Enum] = {
    (Phase.STARTING, Event.STARTED): Phase.TICK_OPEN,
    (Phase.STARTING, Event.COMPLETE): Phase.CLOSING,
    (Phase.TICK_OPEN, Event.TICK_CLOSED): Phase.TICK_OPEN,
    (Phase.TICK_OPEN, Event.COMPLETE): Phase.CLOSING,
    **{(phase, Event.FINISH): Phase.DONE for phase in Phase if phase is not Phase.DONE},
}
"""Every move the world's machine makes: ``(phase, event) -> next phase``."""


class WorldMachine(Machine):
    """The lockstep world of a run (see the module docstring)."""

    TRANSITIONS = TRANSITIONS
    FINAL = Phase.DONE

    def __init__(self, config: SwarmConfig, now: float, first_episode: int = 0,
                 first_tick: int = 0, startup_timeout_s: float | None = None,
                 trace: TickTrace = _NO_TRACE, table=None, incarnation: int = 0) -> None:
        """``table``: the shared ``(Q_DS, Q_CA)`` a resumed run continues from (``--resume``);
        ``incarnation``: which start of the run's world this is (``Observation.world``)."""
        self.config = config
        self.n = config.n_agents
        self.world = SwarmWorld(config, first_episode, first_tick, table)
        self.world.incarnation = incarnation
        self.trace = trace
        self._out: list = []
        self.inbox = Inbox(config.run_id, EffectLog(self))
        self.alive: set[int] = set()
        self.awaited: set[int] = set()  # the live agents whose intent the open tick still awaits
        self.joined: set[int] = set()  # every agent seen alive once
        self.to_resync: set[int] = set()  # to be sent the whole table from their next intent
        self.resumed = first_episode > 0 or first_tick > 0
        self.phase = Phase.STARTING
        self.startup_timeout_s = startup_timeout_s or startup_timeout(config.n_agents)
        self.startup_by = now + self.startup_timeout_s
        self.created = now
        self.startup_s: float | None = None  # until every agent was alive
        self.completed = False
        self.shutdowns_left = SHUTDOWN_TRIES
        self.leave_by = 0.0  # with no live agent, done from then on
        self.next_shutdown = 0.0
        if first_episode >= config.episodes:  # resumed after the last row: only the goodbyes
            self.phase = Phase.CLOSING
            self.leave_by = now + SHUTDOWN_REPEAT_S  # time for the agents' tokens to come
            self.next_shutdown = now
        self.intents = np.full(0, -1, dtype=np.int64)  # the open tick's actions, -1 for none
        self.orders: list[tuple[int, ...] | None] = []  # and their orders (--arbitration pibt)
        self.heard: set[int] = set()  # the agents whose intent for the open tick came
        self.learned: dict[int, tuple] = {}  # the accepted learning records that came with them
        self.tick_start = 0.0
        self.tick_deadline = 0.0
        self.slowest = 0.0  # the episode's slowest tick so far, in seconds
        self.late_ticks = 0  # ticks closed by their deadline without a live agent's intent
        self.episode_start = now
        self.episode_tick = self.world.tick
        self.agent_of_key: dict[str, int] = {}  # intent key -> its agent, parsed once
        shared = self.world.table is not None
        self.records = RecordCheck(config) if shared else None  # see _checked_records
        self.sent: dict = {}  # the open tick's observations, by agent, as they are sent
        self.sent_before: dict = {}  # the last tick's
        self.deciders: tuple = ({}, self.intents, set(), {})  # see _decision
        self.barred: set[int] = set()  # agents that sent a forged record since they started
        self.forged_at: list[tuple[int, int]] = []  # (agent, tick) of each forged record refused
        self.unchecked: set[int] = set()  # the open tick's records still to check
        self.deserted_by: float | None = None  # every agent gone: the run fails then

    # Inputs. Each returns the effects it causes, in the order they must be carried out.

    @an_input
    def on_liveliness(self, key: str, alive: bool, now: float) -> None:
        """An agent's liveliness token (``alive/agent/<id>``) appeared or went."""
        out, phase = self._out, self.phase
        agent = keys.agent_from_key(key, self.config.run_id)
        if agent is None or agent >= self.n:
            self.inbox.reject("unknown-agent", str(key))
        elif phase is Phase.CLOSING:
            (self.alive.add if alive else self.alive.discard)(agent)
            self.leave_by = max(self.leave_by, now + SHUTDOWN_QUIET_S)
        elif alive:
            self.alive.add(agent)
            self.deserted_by = None
            if phase is Phase.TICK_OPEN and self.intents[agent] < 0:
                self.awaited.add(agent)
            out.append(Log(logging.INFO, "agent %d is alive", (agent,)))
            if phase is Phase.TICK_OPEN and agent in self.joined:  # restarted: from a checkpoint
                self.to_resync.add(agent)
                self.barred.discard(agent)  # a new process: its records are checked again
            self.joined.add(agent)
            if phase is Phase.STARTING and len(self.alive) == self.n:
                self._start(now)
        else:
            self.alive.discard(agent)
            self.awaited.discard(agent)
            out.append(Log(logging.WARNING, "agent %d left", (agent,)))
            if not self.alive and phase is Phase.TICK_OPEN and self.deserted_by is None:
                self.deserted_by = now + self.startup_timeout_s
            self._close_if_due(now)

    @an_input
    def on_intent(self, key: str, payload, now: float) -> None:
        """A sample on ``agent/*/intent``: keep the intent; the last one of the tick closes it."""
        key_agent = self.agent_of_key.get(key)
        if key_agent is None:
            key_agent = keys.agent_from_key(key, self.config.run_id)
            if key_agent is not None and key_agent < self.n:
                self.agent_of_key[key] = key_agent  # at most one entry per agent
        intent = self.inbox.decode(payload, Intent, key_agent=key_agent)
        if intent is None:
            return
        tick, intents = self.world.tick, self.intents
        if intent.agent >= self.n:
            self.inbox.reject("unknown-agent", f"agent {intent.agent}")
        elif self.phase is not Phase.TICK_OPEN or intent.tick < tick:
            self.inbox.reject("stale-tick", f"intent for tick {intent.tick} at tick {tick}")
        elif intent.tick > tick:
            self.inbox.reject("future-tick", f"intent for tick {intent.tick} at tick {tick}")
        elif intent.world != self.world.incarnation:  # decided for the world before this one
            self.inbox.reject("other-world", f"intent of agent {intent.agent} for tick "
                                             f"{intent.tick} of world {intent.world}")
        elif intent.episode != self.world.episode:
            self.inbox.reject("wrong-episode", f"episode {intent.episode}")
        elif intent.agent in self.heard:
            self.inbox.reject("duplicate-intent", f"agent {intent.agent} tick {tick}")
        else:
            self.heard.add(intent.agent)
            if intents[intent.agent] < 0:  # a settled agent's action is STAY already
                intents[intent.agent] = intent.action
                self.orders[intent.agent] = intent.order
            self.awaited.discard(intent.agent)
            if intent.record:
                self._keep_record(intent.agent, intent.record[0])
            if intent.agent in self.to_resync:  # it hears the observations: send it the table
                self.to_resync.discard(intent.agent)
                self.world.resync(intent.agent)
            self._close_if_due(now)

    def _keep_record(self, agent: int, record: tuple) -> None:
        """Keep a learning record for the shared table, if it fits it (its intent counts
        either way)."""
        table = self.world.table
        if table is None:
            self.inbox.reject("bad-record", f"agent {agent}: the agents learn apart in this run")
        elif not table.accepts(record):
            self.inbox.reject("bad-record", f"agent {agent}: {record!r:.100}")
        else:
            self.learned[agent] = record
            if self.records is not None:
                self._check_record(agent, False)

    @an_input
    def on_timer(self, now: float) -> None:
        """Time has come to ``now``: a tick's deadline, or the start-up's."""
        phase = self.phase
        if phase is Phase.CLOSING:
            if not self.alive and now >= self.leave_by:
                self._finish(True, None)
            elif now >= self.next_shutdown:
                if self.shutdowns_left:
                    self._send_shutdown(now)
                else:
                    self._finish(True, None)
        elif phase is Phase.STARTING:
            if now >= self.startup_by:
                missing = sorted(set(range(self.n)) - self.alive)
                self._finish(False, f"agents {missing} did not come alive within "
                                    f"{self.startup_timeout_s:.0f} s")
        elif self.deserted_by is not None and now >= self.deserted_by:
            self._finish(False, f"every agent left by tick {self.world.tick} and none came back "
                                f"within {self.startup_timeout_s:.0f} s: the world does not "
                                f"play alone")
        else:
            self._close_if_due(now)

    @an_input
    def stop(self, now: float) -> None:
        """The process is stopping (a signal): tell everyone and end."""
        self._finish(self.phase is Phase.CLOSING, None)

    @property
    def done(self) -> bool:
        return self.phase is Phase.DONE

    def timer(self) -> float | None:
        """When :meth:`on_timer` is next due (None: no timer)."""
        phase = self.phase
        if phase is Phase.CLOSING:
            return self.next_shutdown if self.alive else min(self.next_shutdown, self.leave_by)
        if phase is Phase.STARTING:
            return self.startup_by
        if phase is not Phase.TICK_OPEN:
            return None
        deserted_by = self.deserted_by
        return self.tick_deadline if deserted_by is None else min(self.tick_deadline, deserted_by)

    def stats(self) -> dict:
        return {"completed": self.completed, "ticks": self.world.tick,
                "episode": self.world.episode, "accepted": self.inbox.accepted,
                "rejected": dict(self.inbox.rejections), "violations": self.world.violations,
                "forgers": sorted({agent for agent, _ in self.forged_at}),
                "late_ticks": self.late_ticks, "startup_s": self.startup_s}

    # The clock.

    def _start(self, now: float) -> None:
        self.startup_s = now - self.created
        if self.resumed:  # agents that kept running learned past this world's checkpoint
            self.to_resync.update(range(self.n))
        self.episode_start, self.episode_tick = now, self.world.tick
        if self.world.finished:
            self._close_run(now)
        else:
            self._go(Event.STARTED)
            self._open_tick(now)

    def _open_tick(self, now: float) -> None:
        """Send every agent its observation of the current tick; start waiting for intents."""
        out = self._out
        intents = self.intents = np.full(self.n, -1, dtype=np.int64)
        self.orders = [()] * self.n
        if self.to_resync:
            self.world.unsettle(self.to_resync)
        settled = self.world.settled
        self.awaited = self.alive - settled
        if settled:
            intents[list(settled)] = STAY
        self.heard = set()
        self.learned = {}
        self.unchecked = set()
        self.tick_start = now
        self.tick_deadline = now + self.config.tick_deadline_s
        self.sent_before, self.sent = self.sent, {}
        if self.records is not None:  # what it reads of everyone's plan, for their records
            self.records.plan_tick(self.world.tick, *self.world.sight(), self.world.ending)
        out.append(SendObservations(self._encoded(self.world.observations_by_rank())))

    def _encoded(self, observations):
        """Each observation with its payload, built as it is taken (the first to decide is the
        first to know), kept to check the learning records it leads to."""
        sent = self.sent
        for obs in observations:
            sent[obs.agent] = obs
            yield obs, encode(obs)

    def _close_if_due(self, now: float) -> None:
        """Close the open tick if every live agent's intent is in or its deadline passed."""
        if self.phase is Phase.TICK_OPEN and (now >= self.tick_deadline or not self.awaited):
            self._close_tick(now)

    def _close_tick(self, now: float) -> None:
        """Apply the open tick, open the next (the agents think while this one is reported)."""
        out, world = self._out, self.world
        self.trace.mark(CLOSE, world.tick)
        if self.awaited:
            self._closed_late()
        learned = self._checked_records() if self.records is not None else self.learned
        actions = [None if a < 0 else a for a in self.intents.tolist()]  # None: missed
        report = world.apply(actions, learned, self.orders)
        self.slowest = max(self.slowest, now - self.tick_start)
        if not world.finished:
            self._go(Event.TICK_CLOSED)
            self._open_tick(now)
        if report.violations:
            out.append(Log(logging.ERROR, "tick %d broke the world's invariants: %s",
                           (report.tick, report.violations)))
        out.append(TickClosed(report))
        if report.episode_row is not None:
            out.append(WriteRow(report.episode_row, now - self.episode_start,
                                world.tick - self.episode_tick, self.slowest,
                                self.inbox.total_rejected, report.table))
            self.episode_start, self.episode_tick, self.slowest = now, world.tick, 0.0
        if world.finished:
            self._close_run(now)

    def _closed_late(self) -> None:
        """Count the open tick as closed by its deadline without the intents of the live agents
        still awaited, and say which (:data:`LATE_LOG_FIRST`, :data:`LATE_LOG_EVERY`)."""
        self.late_ticks += 1
        late = self.late_ticks
        if late <= LATE_LOG_FIRST or late % LATE_LOG_EVERY == 0:
            self._out.append(Log(logging.WARNING, "tick %d closed at its %.3g s deadline without "
                                                  "the intents of live agents %s (%d such ticks)",
                                 (self.world.tick, self.config.tick_deadline_s,
                                  sorted(self.awaited), late)))

    def _check_record(self, agent: int, final: bool) -> None:
        """Check agent ``agent``'s record of the open tick (``world.records``) against its
        decision of the tick before, as soon as every intent it may have decided with is in (or
        the tick closes: ``final``); a record that is not its own transition's is dropped and
        counted (a forged one bars the agent's later records until it restarts)."""
        record, check = self.learned[agent], self.records
        assert check is not None  # records are checked only where the swarm shares one table
        decision, obs = self._decision(agent), self.sent.get(agent)
        if agent in self.barred:
            reason = BARRED
        elif (decision is None or obs is None or obs.episode != decision.obs.episode
              or obs.tick != decision.obs.tick + 1):
            reason = UNCHECKED
        elif not (final or check.ready(obs, self.intents)):
            self.unchecked.add(agent)
            return
        elif check.could_write(record, decision, obs, self.intents):
            self.unchecked.discard(agent)
            return
        else:
            reason = FORGED
            self.barred.add(agent)
            self.forged_at.append((agent, self.world.tick))
        self.unchecked.discard(agent)
        del self.learned[agent]
        self.inbox.reject(reason, f"agent {agent} at tick {self.world.tick}: {record!r:.100}")

    def _checked_records(self) -> dict[int, tuple]:
        """The open tick's records, every one checked (:meth:`_check_record`); then what this
        tick's decisions are read from, for the next tick's records (:meth:`_decision`)."""
        for agent in sorted(self.unchecked):
            self._check_record(agent, True)
        self.deciders = (self.sent, self.intents, self.heard, self.sent_before)
        return self.learned

    def _decision(self, agent: int) -> Decision | None:
        """What the world saw of ``agent``'s decision at the last closed tick, where it heard
        the agent decide: read when its record comes, not as the tick closes (every agent
        waits for the world then). ``deciders``: that tick's observations, intents, agents
        heard, and the observations of the tick before."""
        sent, intents, heard, sent_before = self.deciders
        obs = sent.get(agent)
        if obs is None or agent not in heard or not decides(obs, self.config.lifelong):
            return None
        return Decision(obs, intents, sent_before.get(agent))

    def _close_run(self, now: float) -> None:
        """The run is complete: tell the agents until every live one has left (and
        :data:`SHUTDOWN_QUIET_S` passed), :data:`SHUTDOWN_TRIES` times at most."""
        self._go(Event.COMPLETE)
        self.leave_by = now + SHUTDOWN_QUIET_S
        self._send_shutdown(now)

    def _send_shutdown(self, now: float) -> None:
        self.next_shutdown = now + SHUTDOWN_REPEAT_S
        self.shutdowns_left -= 1
        control = Control(self.config.run_id, self.world.tick, WORLD_SENDER, CONTROL_SHUTDOWN)
        self._out.append(SendControl(control, encode(control)))

    def _finish(self, completed: bool, error: str | None) -> None:
        """The end: a completed run has told its agents already; otherwise tell them now."""
        if self.phase is not Phase.CLOSING:
            self._send_shutdown(0.0)
        self._go(Event.FINISH)
        self.completed = completed
        self._out.append(Finished(completed, error))
