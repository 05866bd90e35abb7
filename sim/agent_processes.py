"""The agents' processes on the simulated network: each agent's protocol machine started, from
its checkpoint as ``agent.restore`` starts it, crashed, and its effects carried: intents to the
world, asks to its neighbours as queries and their replies back, checkpoints to disk. A part of
``sim.distributed.SimSwarm``, whose state it shares."""

import msgspec

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.agent_machine import AgentMachine
from nnql_swarm.agent.restore import start_brain
from nnql_swarm.protocol.effects import (
    Ask, Checkpoint, EndQuery, Reply, ReplyError, SendIntent, Stopped,
)
from nnql_swarm.protocol.messages import encode
from nnql_swarm.sim.forgery import forged
from nnql_swarm.sim.swarm_state import Query, SwarmState

START_SPREAD_S = 0.005
"""The agents' processes come up within this long of the world's."""


class AgentProcesses(SwarmState):
    """The agents' side of :class:`~sim.distributed.SimSwarm`."""

    def _start_agent(self, i: int, resume: bool, episode: int | None = None) -> None:
        """Start agent ``i``'s process: afresh, or (``resume``) from its checkpoint's newest
        version, or that of ``episode`` (a resumed run's cut)."""
        if self.world_done or (resume and self.run_over):
            return
        a, net, c = self.agents[i], self.net, self.config
        a.incarnation += 1
        a.alive, a.stalled_until, a.waiting, a.timer_at = True, 0.0, [], None
        if i in self.checkpointed:
            brain, resumed = start_brain(i, c, agent_checkpoint.checkpoint_path(self._checkpoints(), i),
                                         resume, episode=episode)
        else:
            brain, resumed = AgentBrain(i, c), None
        if resume:
            saved = self.saved[i] if episode is None else (episode, self.saved_at[i][episode])
            self.checker.restarted(i, resumed, saved)
        self.protocols[i] = AgentMachine(i, c, brain, net.now)
        net.send_reliable(a, self.world, self._tokens_to_world, [i], True)
        present = []
        for j, b in enumerate(self.agents):
            if b.alive:
                present.append(j)
                if j != i:
                    net.send_reliable(a, b, self._tokens_in, j, [i], True)
        net.send_reliable(None, a, self._tokens_in, i, present, True)
        self._arm_agent(i)

    def _agent_exit(self, i: int, by_world: bool) -> None:
        a, net = self.agents[i], self.net
        if by_world:
            self.final_brains[i] = self._machine(i).brain
        a.alive, a.waiting, a.timer_at = False, [], None
        self.protocols[i] = None
        net.send_reliable(None, self.world, self._tokens_to_world, [i], False)
        for j, b in enumerate(self.agents):
            if b.alive:
                net.send_reliable(None, b, self._tokens_in, j, [i], False)
        for q in self.received.values():  # the asker's Zenoh ends a query whose queryable is gone
            if q.target == i and q.open:
                net.send_reliable(None, self.agents[q.asker], self._ask_ended, q)
        self.received = {number: q for number, q in self.received.items() if q.target != i}
        self._all_gone()

    def _crash_agent(self, i: int) -> None:
        if self.agents[i].alive:
            self._agent_exit(i, by_world=False)

    def _agent_effects(self, i: int, effects: list) -> None:
        net, a = self.net, self.agents[i]
        for effect in effects:
            kind = type(effect)
            if kind is Reply:
                answer = effect.answer
                self.checker.announced(i, answer.tick, answer.action, answer.relayed, "answer")
                q = self.received.get(effect.query)
                if q is not None:
                    arrival = net.send(a, self.agents[q.asker], self._answer_in, q, effect.payload)
                    if arrival > q.last_reply:
                        q.last_reply = arrival
            elif kind is SendIntent:
                intent, payload = effect.intent, effect.payload
                self.checker.announced(i, intent.tick, intent.action, (), "intent")
                if intent.record and self.forging.get(i) == a.incarnation:
                    intent = msgspec.structs.replace(intent, record=(forged(intent.record[0]),))
                    payload = encode(intent)
                    self.checker.forged(i, intent.tick, intent.record[0])
                net.send(a, self.world, self._intent_in, self.intent_keys[i], payload, i,
                         intent.tick, self.checker.era_of(i, intent.tick))
            elif kind is Ask:
                self._ask(i, effect)
            elif kind is ReplyError:
                q = self.received.get(effect.query)
                if q is not None:
                    arrival = net.send(a, self.agents[q.asker], self._refusal_in, q)
                    if arrival > q.last_reply:
                        q.last_reply = arrival
            elif kind is EndQuery:
                q = self.received.pop(effect.query, None)
                if q is not None and q.open:
                    net.send(a, self.agents[q.asker], self._ask_ended, q, not_before=q.last_reply)
            elif kind is Checkpoint:
                if i in self.saving:
                    brain = self._machine(i).brain
                    agent_checkpoint.save(agent_checkpoint.checkpoint_path(self._checkpoints(), i), brain,
                                    effect.episode)
                    tables = agent_checkpoint.fingerprint(brain)
                    self.saved[i] = (effect.episode, tables)
                    self.saved_at[i][effect.episode] = tables
            elif kind is Stopped:
                self._agent_exit(i, by_world=effect.by_world)
                return
        self._arm_agent(i)

    def _ask(self, i: int, effect: Ask) -> None:
        net, a = self.net, self.agents[i]
        target = self.agents[effect.agent]
        q = Query(i, a.incarnation, effect.ask, effect.agent)
        if target.alive:
            net.send(a, target, self._query_in, effect.agent, q, effect.parameters)
            net.local(a, effect.timeout_s, self._ask_ended, q)
        else:  # no queryable: Zenoh ends the query at once
            net.local(a, net.latency(), self._ask_ended, q)

    def _arm_agent(self, i: int) -> None:
        a = self.agents[i]
        if not a.alive:
            return
        due = self._machine(i).timer()
        if due is not None and (a.timer_at is None or due < a.timer_at):
            a.timer_at = due
            self.net.local(a, max(due - self.net.now, 0.0), self._agent_wake, i, due)

    def _agent_wake(self, i: int, due: float) -> None:
        a = self.agents[i]
        if a.timer_at != due:
            return
        a.timer_at = None
        self._agent_timer(i)

    def _agent_timer(self, i: int) -> None:
        protocol = self._machine(i)
        due = protocol.timer()
        if due is not None and due <= self.net.now:
            self._agent_effects(i, protocol.on_timer(self.net.now))
        else:
            self._arm_agent(i)

    def _observation_in(self, i: int, era: int, tick: int, payload: bytes) -> None:
        self.checker.observation_in(i, era, tick)
        self._agent_effects(i, self._machine(i).on_observation(payload, self.net.now))

    def _control_in(self, i: int, payload: bytes) -> None:
        self._agent_effects(i, self._machine(i).on_control(payload, self.net.now))

    def _world_token_in(self, i: int, alive: bool) -> None:
        self._agent_effects(i, self._machine(i).on_world(alive, self.net.now))

    def _tokens_in(self, i: int, agents: list[int], alive: bool) -> None:
        now = self.net.now
        for j in agents:
            protocol = self.protocols[i]
            if protocol is None:
                return
            self._agent_effects(i, protocol.on_liveliness(self.alive_keys[j], alive, now))

    def _query_in(self, i: int, q: Query, parameters: str) -> None:
        number = self.next_query  # each query that arrives is one to its target (a duplicate too)
        self.next_query += 1
        self.received[number] = q
        self._agent_effects(i, self._machine(i).on_query(number, parameters, self.net.now))

    def _answer_in(self, q: Query, payload: bytes) -> None:
        if q.open and self.agents[q.asker].incarnation == q.asker_incarnation:
            self._agent_effects(q.asker, self._machine(q.asker).on_answer(q.ask, payload,
                                                                           self.net.now))

    def _refusal_in(self, q: Query) -> None:
        if q.open and self.agents[q.asker].incarnation == q.asker_incarnation:
            self._agent_effects(q.asker, self._machine(q.asker).on_refusal(q.ask, self.net.now))

    def _ask_ended(self, q: Query) -> None:
        if q.open:
            q.open = False
            if self.agents[q.asker].incarnation == q.asker_incarnation:
                self._agent_effects(q.asker, self._machine(q.asker).on_ask_end(q.ask,
                                                                                self.net.now))
