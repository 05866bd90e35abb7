"""One agent's side of the swarm protocol, pure: inputs in, effects (``protocol.effects``) out.

No sockets, no threads, no clock reads, no files. Every input carries the time ``now`` it
happens at and returns the effects it causes, in order; :meth:`AgentMachine.timer` is when it
next wants :meth:`AgentMachine.on_timer`. ``agent.agent_node`` runs it over Zenoh, ``sim`` over a
simulated network in virtual time.

Theory of operation. The machine is in one ``Phase`` at a time, moved only by ``TRANSITIONS``
(``agent.phases``; ``protocol.phase_machine`` runs an input):

- ``PEERS``: until it has seen every other agent's liveliness token (or given up waiting, at
  ``ready_by``), observations are kept in order, and handled once it is ``IDLE``. Where it is
  told to (``rejoin_deaf_s``), an agent that has heard no other agent by ``deaf_by`` takes its
  session for deaf and stops, for its node to open another (``Stopped.rejoin``).
- ``IDLE``: waiting for an observation, in tick order. One whose decision awaits no intent (as
  ``agent.negotiation`` plans it) is decided at once; otherwise the agent is ``NEGOTIATING``.
- ``NEGOTIATING``: it learns the intents of the visible higher-ranked neighbours from the
  standing queries it keeps open on the agents near it (``?since=T;from=<id>``), answered
  by each neighbour whose plan asks it, and, where no standing query is open yet, with one ask
  each (``?tick=T;from=<id>``); answers relay what their senders learned. Once every asked
  neighbour answered, refused, or the negotiation timed out, it asks directly for any awaited
  intent no answer brought (``ASKING_MISSING``), then decides with what it knows and is ``IDLE``
  again.
- ``STOPPED``: the world said so, or the process is stopping; inputs do nothing.

A decision answers the standing and held queries the agent owes (the next in rank first) and
sends its intent for the world, unless the observation says it is settled (parked on its goal
since an earlier tick: the world needs no intent from it) and it has nothing learned to send. An
announced intent never changes. At an episode's end it checkpoints before it sends the intent,
so that no learned value is lost to a crash. Queries for its intent are answered in every phase
but ``STOPPED``: at once for a decided tick, else held until the decision. Once it has arrived,
where settled agents are quiet (``SwarmConfig.quiet_settled``), the world skips its ticks until
the episode's end tick or until it owes it a catch-up of the shared table (``world.engine``):
within that episode, a later tick is not a gap.

A decision made without an intent it needed (the negotiation timed out, or the neighbour
refused) may differ from the one a run without faults makes: its episode is counted
(``decided_short`` in the agent's stats), so that a run can be compared with one without faults
up to there.

Faults it survives: an observation lost on the way (it follows the clock again after
:data:`RESYNC_AFTER` observations in a row), an answer lost or late (the negotiation times out;
the standing query is replaced, at once if it ends mid-negotiation), a neighbour that dies or
refuses the tick (its ask ends unanswered, or with an error: it is waited for no more), a world
that dies and comes back with its own clock (``--resume``: the agent starts afresh, and ignores
whatever is still on its way from the world before, never deciding again a tick it decided for
that world: ``stale-tick``; a world gone for longer than
``world_wait_s`` is taken for gone for good: the agent stops, ``world_lost``), forged or
malformed input (rejected and counted by reason, never raised). ``launch/faultsim.py`` runs it through thousands of seeded
fault schedules (``sim``).
"""

import logging

from nnql_swarm.agent import negotiation
from nnql_swarm.agent.answering import AHEAD_TICKS, QueryAnswering
from nnql_swarm.agent.phases import TRANSITIONS, WAITING, Event, OpenAsk, Pending, Phase
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.actions import STAY
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, START_S_PER_AGENT, SwarmConfig
from nnql_swarm.protocol.effects import (
    Ask, Checkpoint, EndQuery, EpisodeEnded, Log, SendIntent, Stopped,
)
from nnql_swarm.protocol.inbox import Inbox
from nnql_swarm.protocol.messages import (
    CONTROL_SHUTDOWN, Answer, Control, Intent, Observation, agent_sender, encode,
)
from nnql_swarm.protocol.phase_machine import EffectLog, Machine, an_input, any_phase_input
from nnql_swarm.protocol.trace import ACTED, ANSWER_IN, DECIDE, ENCODED, OBS_IN, TickTrace

RESYNC_AFTER = 3
"""Consecutive observations past a gap in the ticks after which an agent follows them."""

STANDING_QUERY_S = 600.0
"""Lifetime of a standing query; when it ends, the agent opens another after its next decision."""

PEER_WAIT_S = 30.0
"""How long an agent waits at least, at start-up, to see every other agent before it acts anyway
(``protocol.config.START_S_PER_AGENT`` per agent, where that is longer)."""

WORLD_WAIT_S = 300.0
"""How long an agent waits at most for a world that left to come back (``--world-wait``): a
world restarted with ``--resume`` comes back sooner; one that completed the run while this
agent was cut off never does."""

_NOTHING = negotiation.TickIntents()
"""What an agent knows of a tick nobody answered for (never written to)."""

_NO_TRACE = TickTrace("agent", None)


class AgentMachine(QueryAnswering, Machine):
    """The negotiation of one agent (see the module docstring); ``brain`` decides."""

    TRANSITIONS = TRANSITIONS
    FINAL = Phase.STOPPED

    def __init__(self, agent: int, config: SwarmConfig, brain, now: float,
                 negotiation_timeout_s: float | None = None, trace: TickTrace = _NO_TRACE,
                 world_wait_s: float = WORLD_WAIT_S, rejoin_deaf_s: float = 0.0) -> None:
        """``brain`` is an ``agent.brain.AgentBrain`` (fresh, or restored from a checkpoint);
        ``trace`` only records the time of each step (``protocol.trace``), never decides;
        ``world_wait_s``: how long a world that left may stay away; ``rejoin_deaf_s``: how long
        its session may hear no other agent before it stops to rejoin (0: as long as it takes)."""
        self.agent = agent
        self.config = config
        self.brain = brain
        self.planner = negotiation.Planner(config)
        self.n = config.n_agents
        self.sender = agent_sender(agent)
        self.timeout_s = (config.tick_deadline_s / 2 if negotiation_timeout_s is None
                          else negotiation_timeout_s)
        self.negotiates = config.algo in NEGOTIATING_ALGOS and self.n > 1
        self.trace = trace
        self._out: list = []
        self.inbox = Inbox(config.run_id, EffectLog(self))
        self.phase = Phase.IDLE if self.n == 1 else Phase.PEERS
        self.ready_by = now + max(PEER_WAIT_S, START_S_PER_AGENT * self.n)
        self.rejoin_deaf_s = rejoin_deaf_s
        self.deaf_by = now + rejoin_deaf_s if rejoin_deaf_s > 0 and self.n > 1 else None
        self.early: list = []  # observations that came while waiting for the peers, in order
        self.peers_seen: set[int] = set()
        self.pending: Pending | None = None  # while NEGOTIATING or ASKING_MISSING
        self.decided_tick = -1
        self.decided_short: dict[int, int] = {}  # episode -> its decisions short of an intent
        self.quiet_episode = -1  # the episode in which the world may skip this agent's ticks,
        self.quiet_first_tick = -1  # and that episode's first tick (``_skipped_while_quiet``)
        self.decided_waiters = []  # whom the decided tick's answer goes to by stream
        self.decided_near: list[int] = []  # the decided tick's Plan.near
        self.decided_answer = None
        self.decided_payload = b""
        self.held = []
        self.standing = {}
        self.standing_seen: dict[int, int] = {}
        self.standing_review_at = self.standing_reviewed = -1
        self.intents: dict[int, negotiation.TickIntents] = {}  # tick -> what was learned of it
        self.asks: dict[int, OpenAsk] = {}
        self.next_ask = 0
        self.streams: dict[int, int] = {}  # neighbour -> generation of its open standing query
        self.stream_generation = 0
        self.gap_tick, self.gap_run = -1, 0
        self.shutdown = False  # stopped by the world
        self.world_wait_s = world_wait_s
        self.world_back_by: float | None = None  # the world left: it must be back by then
        self.decided_world = -1  # the world (its incarnation) whose tick it decided last
        self.decided_before_left: dict[int, int] = {}  # a world that left -> its last tick decided
        self.world_lost = False  # stopped because it was not

    @property
    def stopped(self) -> bool:
        return self.phase is Phase.STOPPED

    # Inputs. Each returns the effects it causes, in the order they must be carried out.

    @an_input
    def on_observation(self, payload, now: float) -> None:
        """The world's observation for this agent."""
        if self.phase is Phase.PEERS:
            self.early.append(payload)
        else:
            self._observe(payload, now)

    @an_input
    def on_answer(self, ask: int, payload, now: float) -> None:
        """A reply to one of this agent's asks (a standing one brings one per tick)."""
        open_ask = self.asks.get(ask)
        if open_ask is not None:
            self._answer_in(open_ask.agent, payload, now)

    @an_input
    def on_ask_end(self, ask: int, now: float) -> None:
        """One of this agent's asks ended: timed out, finished, or its target is gone."""
        open_ask = self.asks.pop(ask, None)
        if open_ask is None:
            return
        p = self._negotiation()
        if open_ask.generation is not None:
            j = open_ask.agent
            if self.streams.get(j) == open_ask.generation:
                del self.streams[j]
                if (p is not None and self.phase is Phase.NEGOTIATING and p.deadline > now
                        and j in p.plan.asks and j not in self._intents_of(p.obs.tick).answered):
                    self._ask(j, p.obs.tick, p.deadline - now)  # not by the stream
        elif open_ask.agent not in self.peers_seen:  # gone: no answer is coming
            self._refused(open_ask, now)

    @an_input
    def on_refusal(self, ask: int, now: float) -> None:
        """An error reply to one of this agent's asks: the neighbour cannot answer that tick
        (it is behind, or past it)."""
        open_ask = self.asks.get(ask)
        if open_ask is not None and open_ask.generation is None:
            self._refused(open_ask, now)

    @any_phase_input
    def on_liveliness(self, key: str, alive: bool, now: float) -> None:
        """An agent's liveliness token (``alive/agent/<id>``) appeared or went."""
        agent = keys.agent_from_key(key, self.config.run_id)
        if agent is None or agent >= self.n:  # a token of no agent of this run: nobody to ask
            self.inbox.reject("unknown-agent", str(key))
        elif alive:
            self.peers_seen.add(agent)
            if agent != self.agent:
                self.deaf_by = None  # the session hears the others
            if self.phase is Phase.PEERS and self._every_peer_seen():
                self._become_ready(now)
        else:
            self.peers_seen.discard(agent)
            self.streams.pop(agent, None)  # ask its next incarnation afresh
            query = self.standing.pop(agent, None)
            self.standing_seen.pop(agent, None)
            if query is not None:
                self._out.append(EndQuery(query))

    @any_phase_input
    def on_world(self, alive: bool, now: float) -> None:
        """The world's liveliness token appeared or went. A world that leaves may come back
        (``--resume``) with its own clock: start afresh."""
        self.world_back_by = None if alive else now + self.world_wait_s
        if not alive:
            self._out.append(Log(logging.INFO, "the world left; waiting for it to come back"))
            before = self.decided_before_left
            before[self.decided_world] = max(before.get(self.decided_world, -1), self.decided_tick)
            self.decided_tick = -1
            if self.phase is not Phase.STOPPED:
                self._go(Event.WORLD_LEFT)
            self.pending = None
            self.brain.learner.forget_pending()
            self.intents = {}
            self._drop_held()
            # A world that comes back replays tick numbers: what is still on its way from this
            # one's ticks must not count for the next one's. Replies to the asks made so far
            # are ignored from now on, and the standing queries are opened afresh.
            self.asks = {}
            self.streams = {}

    @any_phase_input
    def on_control(self, payload, now: float) -> None:
        """A control message from the world (shutdown)."""
        control = self.inbox.decode(payload, Control)
        if (control is not None and control.command == CONTROL_SHUTDOWN
                and self.phase is not Phase.STOPPED):
            self._out.append(Log(logging.INFO, "shutdown from the world"))
            self.shutdown = True
            self._stop(by_world=True)

    @an_input
    def on_timer(self, now: float) -> None:
        """Time has come to ``now``: start without the peers not seen (or stop to rejoin, having
        heard none), end a negotiation, or stop waiting for a world that left."""
        if self.world_back_by is not None and now >= self.world_back_by:
            self._out.append(Log(logging.ERROR, "no world for %.0f s (--world-wait): taken for "
                                                "gone for good; stopping", (self.world_wait_s,)))
            self.world_lost = True
            self._stop(by_world=False)
            return
        if self.phase is Phase.PEERS and self.deaf_by is not None and now >= self.deaf_by:
            self._out.append(Log(logging.WARNING, "heard no other agent in %.0f s: opening the "
                                                  "session again", (self.rejoin_deaf_s,)))
            self._stop(by_world=False, rejoin=True)
            return
        if self.phase is Phase.PEERS and now >= self.ready_by:
            self._out.append(Log(logging.WARNING, "only saw agents %s; negotiating with whoever "
                                                  "answers", (sorted(self.peers_seen),)))
            self._become_ready(now)
        p = self._negotiation()
        if p is not None and now >= p.deadline:
            self._advance(now)

    @an_input
    def stop(self, now: float) -> None:
        """The process is stopping (a signal): finish every query held."""
        self._stop(by_world=False)

    def timer(self) -> float | None:
        """When :meth:`on_timer` is next due (None: no timer)."""
        phase = self.phase
        if phase is Phase.PEERS:
            due: float | None = min(self.ready_by, self.deaf_by or self.ready_by)
        else:
            p = self._negotiation()
            due = None if p is None else p.deadline
        back_by = self.world_back_by
        if back_by is None or phase is Phase.STOPPED:
            return due
        return back_by if due is None else min(due, back_by)

    def stats(self) -> dict:
        return {"agent": self.agent, "decided_tick": self.decided_tick,
                "accepted": self.inbox.accepted, "rejected": dict(self.inbox.rejections),
                "shutdown_by_world": self.shutdown, "world_lost": self.world_lost,
                "decided_short": dict(self.decided_short)}

    # The negotiation.

    def _every_peer_seen(self) -> bool:
        return len(self.peers_seen - {self.agent}) >= self.n - 1

    def _become_ready(self, now: float) -> None:
        """Handle the observations that came while waiting for the peers, in order."""
        self._go(Event.READY)
        early, self.early = self.early, []
        for payload in early:
            self._observe(payload, now)

    def _observe(self, payload, now: float) -> None:
        """Start a tick: decide at once if no intent is awaited, else ask and wait for them."""
        arrived = self.trace.now()
        obs = self.inbox.decode(payload, Observation)
        if obs is None:
            return
        self.trace.mark(OBS_IN, obs.tick, at=arrived)
        if obs.agent != self.agent:
            self.inbox.reject("wrong-agent", f"observation for agent {obs.agent}")
            return
        if self._past_its_episode(obs):
            self.inbox.reject("future-tick", f"tick {obs.tick}, step {obs.step} of episode "
                                             f"{obs.episode}: past that episode's ticks")
            return
        if self._before_the_world_left(obs):
            return
        p = self._negotiation()
        if p is not None and obs.tick == p.obs.tick + 1:
            self._decide_pending()  # the world has moved on (this agent stalled): decide now
        if obs.tick <= self.decided_tick:
            self.inbox.reject("stale-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        if (self.decided_tick >= 0 and obs.tick != self.decided_tick + 1
                and not self._skipped_while_quiet(obs) and not self._resync(obs)):
            self.inbox.reject("future-tick", f"tick {obs.tick} after {self.decided_tick}")
            return
        plan = self.planner(obs)
        if plan is None:  # forged: compiled kernels must not read past their buffers
            self.inbox.reject("bad-field:neighbours", f"tick {obs.tick}: not this run's agents "
                                                      "on its grid")
            return
        awaited, asks = plan.awaited, plan.asks
        needed = self.brain.neighbours_to_ask(obs, awaited)
        staying = {j: STAY for j in plan.staying}
        if not awaited:
            self._decide(obs, plan, staying)
            return
        tick = obs.tick
        got = self._intents_of(tick)
        for j in asks:
            if j not in got.answered and j not in self.streams:
                self._ask(j, tick, self.timeout_s)
        self._go(Event.AWAITS)
        self.pending = Pending(obs, plan.kept(), needed, now + self.timeout_s, staying)
        self.brain.prepare(obs)  # while the answers are on their way
        self._advance(now)

    def _negotiation(self) -> Pending | None:
        """The observation whose decision waits for intents, while the agent waits for them
        (``NEGOTIATING``, ``ASKING_MISSING``); else None."""
        if self.phase not in WAITING:
            return None
        assert self.pending is not None
        return self.pending

    def _refused(self, open_ask: OpenAsk, now: float) -> None:
        """No answer is coming for this ask: the pending negotiation waits for it no more."""
        p = self._negotiation()
        if (p is not None and open_ask.tick == p.obs.tick
                and open_ask.agent not in self._intents_of(p.obs.tick).answered):
            p.refused.add(open_ask.agent)
            self._advance(now)

    def _intents_of(self, tick: int) -> negotiation.TickIntents:
        """What this agent has learned of ``tick``'s intents (kept from now on)."""
        got = self.intents.get(tick)
        if got is None:
            got = self.intents[tick] = negotiation.TickIntents()
        return got

    def _advance(self, now: float) -> None:
        """Move the pending negotiation on: once every asked neighbour answered (or time ran
        out), ask directly for any awaited intent that no answer brought; once those are in
        too (or time ran out), decide. Unanswered neighbours are left out."""
        p = self._negotiation()
        assert p is not None
        got = self._intents_of(p.obs.tick)
        remaining = p.deadline - now
        refused = p.refused
        if self.phase is Phase.NEGOTIATING:
            if remaining > 0 and not all(j in got.answered or j in refused for j in p.plan.asks):
                return
            for j in p.plan.asks:
                if j not in got.answered:
                    self.streams.pop(j, None)  # it did not answer in time: open a fresh one
            self._go(Event.ANSWERS_IN)
            p.missing = [j for j in p.plan.awaited if j not in got.actions and j not in refused]
            if p.missing and remaining > 0:
                for j in p.missing:
                    self._ask(j, p.obs.tick, remaining)
                return
        elif remaining > 0 and not all(j in got.actions or j in refused for j in p.missing):
            return
        self._decide_pending()

    def _decide_pending(self) -> None:
        self._go(Event.DECIDED)
        p, self.pending = self.pending, None
        assert p is not None
        known = self.intents.get(p.obs.tick, _NOTHING).actions
        if any(j not in known for j in p.needed):  # timed out, or refused: may differ
            episode = p.obs.episode
            self.decided_short[episode] = self.decided_short.get(episode, 0) + 1
        answers = {**p.staying, **{j: known[j] for j in p.needed if j in known}}
        self._decide(p.obs, p.plan, answers)

    def _decide(self, obs: Observation, plan: negotiation.Plan, answers: dict[int, int]) -> None:
        """Decide ``obs`` with the ``answers`` of the neighbours the brain waits for; answer
        for it, relaying every intent learned for the tick; checkpoint at an episode's end;
        tell the world."""
        out, trace, tick = self._out, self.trace, obs.tick
        trace.mark(DECIDE, tick)
        refused = self.brain.rejected_updates
        action = self.brain.act(obs, answers, (plan.cells, plan.parked))
        trace.mark(ACTED, tick)
        if self.brain.rejected_updates != refused:
            self.inbox.reject("bad-update", f"{self.brain.rejected_updates - refused} shared-table "
                                            f"entries refused at tick {tick} (outside the "
                                            "tables, or in a group of uneven lengths)")
        known = self.intents.get(tick, _NOTHING).actions
        answer = Answer(self.config.run_id, tick, self.sender, self.agent, obs.episode, action,
                        tuple(sorted(known.items())))
        self.decided_tick, self.decided_answer, self.decided_world = tick, answer, obs.world
        if obs.arrived and self.config.quiet_settled:  # quiet from the next tick (world.engine)
            self.quiet_episode, self.quiet_first_tick = obs.episode, tick - obs.step
        self.decided_waiters = plan.answered
        if self.negotiates:
            self.decided_near = plan.near
        self.decided_payload = encode(answer)
        trace.mark(ENCODED, tick)
        self.intents = {t: got for t, got in self.intents.items() if t > tick}
        if self.standing:
            self._answer_standing_queries()
        if self.held:
            self._answer_held()
        if obs.episode_end:  # saved before the world hears of the decision: nothing to lose
            out.append(Checkpoint(obs.episode))
        learned = self.brain.learned
        if learned or not obs.settled:  # settled: the world expects no intent (world.engine)
            intent = Intent(answer.run, tick, answer.sender, self.agent, obs.episode, action,
                            learned, self.brain.order, obs.world)
            out.append(SendIntent(intent, encode(intent)))
        if obs.episode_end:
            out.append(EpisodeEnded(obs.episode))
        if self.negotiates and not obs.episode_end:  # a new episode places everyone anew
            self._open_streams(tick + 1)

    def _past_its_episode(self, obs: Observation) -> bool:
        """Whether no world of this run could send ``obs``: a step past ``max_steps``, an
        episode past the run's, or a tick past the latest its episode can reach
        (``SwarmConfig.episode_ticks``). An agent takes the first observation it gets at its
        word, whatever its tick; this keeps a forged far tick from setting its clock."""
        c = self.config
        return (obs.step > c.max_steps or obs.episode >= c.episodes
                or obs.tick - obs.step > obs.episode * c.episode_ticks)

    def _before_the_world_left(self, obs: Observation) -> bool:
        """Whether ``obs`` is a tick this agent decided for its world before that world left
        (a copy still on its way): refused and counted (``stale-tick``). Once the world left,
        the agent takes its next observation at its word (:meth:`on_world`): the same world,
        reached again, goes on from later ticks, and a world started again is another
        incarnation (``Observation.world``), whose ticks are its own. So a world's tick is
        decided once, and an intent announced for it never changes."""
        last = self.decided_before_left.get(obs.world)
        if last is not None and obs.tick <= last:
            self.inbox.reject("stale-tick", f"tick {obs.tick} of world {obs.world}, decided "
                                            f"before it left (tick {last})")
            return True
        return False

    def _skipped_while_quiet(self, obs: Observation) -> bool:
        """Whether ``obs`` is a later tick of the episode in which this agent arrived, which the
        world may reach without it: that episode's number and its first tick (``tick - step`` is
        constant within an episode, ``world.engine``). A message forged with a far tick for that
        episode must not move this agent's clock out of it."""
        return obs.episode == self.quiet_episode and obs.tick - obs.step == self.quiet_first_tick

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
        self._out.append(Log(logging.WARNING, "lost observations before tick %d; following the "
                                              "world's clock again", (obs.tick,)))
        self.gap_run = 0
        return True

    def _new_ask(self, neighbour: int, tick: int, parameters: str, timeout_s: float,
                 generation: int | None = None) -> None:
        ask = self.next_ask
        self.next_ask += 1
        self.asks[ask] = OpenAsk(neighbour, tick, generation)
        self._out.append(Ask(ask, neighbour, parameters, timeout_s))

    def _ask(self, neighbour: int, tick: int, timeout_s: float) -> None:
        """Ask one neighbour for its intent at ``tick``; its answer comes to ``on_answer``."""
        self._new_ask(neighbour, tick, keys.intent_query_params(tick, self.agent), timeout_s)

    def _open_streams(self, since: int) -> None:
        """Open a standing query on the intent key of every agent near enough to be asked soon
        (``negotiation.Plan.near``) that has none; those agents end them once it is far
        (``agent.answering``)."""
        streams, peers = self.streams, self.peers_seen
        new = [j for j in self.decided_near if j not in streams and j in peers]
        if not new or since >= keys.MAX_TICK:
            return
        params = keys.standing_query_params(since, self.agent)
        for j in sorted(new):
            if j != self.agent:
                self.stream_generation += 1
                self._new_ask(j, since, params, STANDING_QUERY_S, self.stream_generation)
                self.streams[j] = self.stream_generation

    def _answer_in(self, sender: int, payload, now: float) -> None:
        """Keep an answer for the coming ticks, and move the negotiation on if it waits for it;
        answers for decided ticks are of no more use (a standing query also brings those this
        agent did not need)."""
        arrived = self.trace.now()
        answer = self.inbox.decode(payload, Answer, key_agent=sender)
        if answer is None or answer.tick <= self.decided_tick:
            return
        self.trace.mark(ANSWER_IN, answer.tick, at=arrived, peer=sender)
        if self.decided_tick >= 0 and answer.tick > self.decided_tick + AHEAD_TICKS:
            self.inbox.reject("future-tick", f"answer for tick {answer.tick}, "
                                             f"decided {self.decided_tick}")
            return
        got = self._intents_of(answer.tick)
        if not got.add(sender, answer.action, answer.relayed, self.agent):
            self.inbox.reject("conflicting-relay", f"agent {sender} at tick {answer.tick}")
        while len(self.intents) > AHEAD_TICKS + 1:  # a flood of forged ticks stays bounded
            del self.intents[min(self.intents)]
        p = self._negotiation()
        if p is not None and p.obs.tick == answer.tick:
            self._advance(now)

    def _stop(self, by_world: bool, rejoin: bool = False) -> None:
        self._drop_held()
        for query in self.standing.values():
            self._out.append(EndQuery(query))
        self.standing = {}
        self.standing_seen = {}
        self.pending = None
        self._go(Event.STOP)
        self._out.append(Stopped(by_world, rejoin))
