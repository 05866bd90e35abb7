"""The swarm on the simulated network: a world and its agents, each its protocol machine, under a
fault schedule, checked as it runs.

This module plays the part that Zenoh, the kernel, the disk and the launcher play for real:
it carries every effect of a protocol (``protocol.effects``) to where it goes, over
``sim.network``'s links: observations and control to the agents, intents to the world, an
agent's asks to its neighbours as queries and their replies back, liveliness tokens to everyone
who subscribes (with the tokens already there, as Zenoh's history gives them). It writes the
world's rows to a simulated ``episodes.csv`` and the agents' checkpoints to real files (of the
agents a schedule may crash; of all with ``checkpoint_all``), restarts a crashed agent from its
checkpoint through ``agent.restore`` as an agent process does, and a crashed world as
``--resume`` does, after the last complete row. The launcher's rule holds: once the world has
said the run is over, no agent is restarted (the launcher stops whatever still runs when the
world exits). Where a schedule kills every process at once, every file a run writes goes to
disk (``config.json``, ``episodes.csv``, every checkpoint, the world's shared table) and the run
is continued as ``launch/swarm.py --resume`` continues it, through the same functions
(``supervision.resume``): from the cut of its files, rows past it dropped.
"""

import hashlib
import tempfile
from dataclasses import dataclass
from pathlib import Path

import msgspec

from nnql_swarm.agent import checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.machine import AgentMachine
from nnql_swarm.agent.restore import start_brain
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.effects import (
    Ask, Checkpoint, EndQuery, Finished, Reply, ReplyError, SendControl, SendIntent,
    SendObservations,
    Stopped, TickClosed, WriteRow,
)
from nnql_swarm.protocol.messages import encode
from nnql_swarm.protocol.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE
from nnql_swarm.sim.checks import Checker
from nnql_swarm.sim.network import Network, Process
from nnql_swarm.sim.forgery import forged
from nnql_swarm.sim.schedule import FORGE, WINDOWS, Fault, Schedule, schedule_rng
from nnql_swarm.supervision.resume import resume_point, rewind, shared_table
from nnql_swarm.world import checkpoint as world_checkpoint
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.machine import WorldMachine

VIRTUAL_LIMIT_S = 3600.0
"""A run still going after this much virtual time did not end."""

EVENT_LIMIT = 2_000_000
"""A run still going after this many events did not end."""

START_SPREAD_S = 0.005
"""The agents' processes come up within this long of the world's."""

REORDER_S = 0.005
"""How long a reordered message is held back at most."""


@dataclass(slots=True)
class Query:
    """One ask in flight: who asked (which incarnation, its ask number), whom, and whether the
    asker still listens."""

    asker: int
    asker_incarnation: int
    ask: int
    target: int
    open: bool = True
    last_reply: float = 0.0  # when its latest reply arrives: its end comes after


@dataclass
class Outcome:
    """What one simulated run gave: its failures (none: it passed), its size, a digest of its
    history (the same seed gives the same digest), the metrics rows and, if asked for, the
    agents' final tables (``checkpoint.fingerprint``)."""

    seed: int
    failures: list[str]
    ticks: int
    events: int
    virtual_s: float
    digest: str
    rows: list[dict]
    fingerprints: list[str] | None = None
    fired: tuple[str, ...] = ()  # the kinds of the faults that hit, in order


class SimSwarm:
    """One run of a :class:`~sim.schedule.Schedule` (see the module docstring)."""

    def __init__(self, schedule: Schedule, disk: Path | None = None,
                 checkpoint_all: bool = False, write_metrics: bool = False) -> None:
        """``disk``: where checkpoints (and, with ``write_metrics``, ``episodes.csv``) go; it
        is needed when the schedule crashes an agent or ``checkpoint_all`` is set."""
        self.schedule = schedule
        c = self.config = schedule.config
        self.n = n = c.n_agents
        self.net = Network(schedule_rng(schedule.seed, 1), schedule.latency)
        self.world = Process("world")
        self.agents = [Process(f"agent-{i}") for i in range(n)]
        self.processes = {p.name: p for p in (self.world, *self.agents)}
        self.world_protocol: WorldMachine | None = None
        self.protocols: list[AgentMachine | None] = [None] * n
        self.final_brains: list[AgentBrain | None] = [None] * n
        self.era = -1
        self.rows: list[dict] = []
        self.resumable = schedule.kills_all  # every file written, for --resume
        checkpoint_all = checkpoint_all or self.resumable
        self.checkpointed = frozenset(range(n)) if checkpoint_all else schedule.crashing_agents
        self.saving = set(self.checkpointed)  # whose checkpoints someone may still read
        self.keep_all = checkpoint_all
        if (self.checkpointed or self.resumable) and disk is None:
            raise ValueError("a schedule that checkpoints needs a disk")
        self.disk = None if disk is None else Path(disk)
        self.checkpoint_dir = None if disk is None else Path(disk) / CHECKPOINT_DIR
        self.write_metrics = write_metrics or self.resumable
        if self.resumable:
            (self.disk / CONFIG_FILE).write_text(c.to_json() + "\n")
        self.writer = EpisodeWriter(self.disk / EPISODES_FILE, sync=False) \
            if self.write_metrics else None
        self.saved: list[tuple[int, str] | None] = [None] * n
        self.saved_at: list[dict[int, str]] = [{} for _ in range(n)]  # episode -> tables
        self.generation = 0  # how often everyone was killed: restarts of earlier ones lapse
        self.received: dict[int, Query] = {}  # a query as its target numbered it -> the ask
        self.next_query = 0
        self.checker = Checker(c)
        self.alive_keys = [keys.alive_key(c.run_id, keys.ROLE_AGENT, i) for i in range(n)]
        self.intent_keys = [keys.intent_key(c.run_id, i) for i in range(n)]
        self.world_done = False
        self.completed = False
        self.run_over = False  # the world has said so: the launcher restarts nobody any more
        self.triggers: dict[int, list[Fault]] = {}
        for fault in schedule.faults:
            self.triggers.setdefault(fault.tick, []).append(fault)
        self.opened: set[int] = set()
        self.fired: list[str] = []
        self.forging: dict[int, int] = {}  # a compromised agent -> the incarnation that forges

    # The run.

    def run(self, fingerprints: bool = False) -> Outcome:
        net = self.net
        self._start_world(0, 0)
        for i in range(self.n):
            net.at(START_SPREAD_S * net.rng.random(), self._start_agent, i, False)
        ended = net.run(VIRTUAL_LIMIT_S, EVENT_LIMIT)
        check = self.checker
        if not ended:
            check.fail(f"the run did not end: {net.events} events, {net.now:.1f} virtual s")
        elif not self.completed:
            check.fail("the world did not complete the run"
                       + ("" if self.world_protocol is None
                          else f" (stuck at tick {self.world_protocol.world.tick})"))
        still = [i for i, a in enumerate(self.agents) if a.alive]
        if still:
            check.fail(f"agents {still} never stopped")
        check.metrics(self.rows, self.config.episodes)
        if self.writer is not None:
            self.writer.close()
        digest = hashlib.sha1(repr((self.rows, net.events, net.now)).encode()).hexdigest()[:12]
        ticks = sum(row["steps"] + 1 for row in self.rows)
        prints = None
        if fingerprints:
            prints = [None if b is None else checkpoint.fingerprint(b) for b in self.final_brains]
        return Outcome(self.schedule.seed, check.failures, ticks, net.events, net.now, digest,
                       self.rows, prints, tuple(self.fired))

    def _all_gone(self) -> None:
        if self.world_done and not any(a.alive for a in self.agents):
            self.net.halted = True

    # The world's process.

    def _start_world(self, first_episode: int, first_tick: int, table=None) -> None:
        w, net = self.world, self.net
        w.incarnation += 1
        w.alive, w.stalled_until, w.waiting, w.timer_at = True, 0.0, [], None
        self.era += 1
        self.world_protocol = WorldMachine(self.config, net.now, first_episode, first_tick,
                                           table=table)
        for i, a in enumerate(self.agents):
            if a.alive:
                net.send_reliable(w, a, self._world_token_in, i, True)
        present = [i for i, a in enumerate(self.agents) if a.alive]
        if present:
            net.send_reliable(None, w, self._tokens_to_world, present, True)
        self._arm_world()

    def _world_exit(self) -> None:
        w, net = self.world, self.net
        w.alive, w.waiting, w.timer_at = False, [], None
        for i, a in enumerate(self.agents):
            if a.alive:
                net.send_reliable(None, a, self._world_token_in, i, False)

    def _crash_world(self) -> None:
        if self.world.alive and not self.world_done:
            self._check_world()
            self._world_exit()

    def _restart_world(self) -> None:
        if self.world_done:
            return
        rows = self.rows
        self._start_world(len(rows), rows[-1]["end_tick"] + 1 if rows else 0)

    def _check_world(self) -> None:
        violations = self.world_protocol.world.violations
        if violations:
            self.checker.fail(f"the world counted {violations} broken invariants")
        self.checker.forgeries_refused(self.era, self.world_protocol.forged_at)

    def _world_effects(self, effects: list) -> None:
        sent = None
        net, world, agents = self.net, self.world, self.agents
        for effect in effects:
            kind = type(effect)
            if kind is SendObservations:
                sent = []
                for obs, payload in effect.observations:
                    sent.append(obs)
                    net.send(world, agents[obs.agent], self._observation_in, obs.agent, self.era,
                             obs.tick, payload)
            elif kind is TickClosed:
                report = effect.report
                if report.records:
                    self.checker.records_applied(self.era, report.tick, report.records)
                if report.episode_row is not None:
                    self.checker.end_heard(report.episode, report.missed)
            elif kind is WriteRow:
                if self.resumable and effect.table is not None:
                    world_checkpoint.save(world_checkpoint.table_path(self.disk), effect.table,
                                          effect.row["episode"], self.config)
                self.rows.append({f: effect.row[f] for f in EPISODE_FIELDS})
                if self.writer is not None:
                    self.writer.write(effect.row, effect.duration_s, effect.ticks,
                                      effect.slowest_s, effect.rejected)
            elif kind is SendControl:
                self.run_over = True
                for i, a in enumerate(agents):
                    net.send(world, a, self._control_in, i, effect.payload)
            elif kind is Finished:
                self._check_world()
                if effect.completed:
                    self.completed = True
                else:
                    self.checker.fail(f"the world gave up: {effect.error}")
                self.world_done = True
                self._world_exit()
                self._all_gone()
                return
        if sent:
            self.checker.tick_sent(self.era, sent)
            tick = sent[0].tick
            if tick not in self.opened:
                self.opened.add(tick)
                for fault in self.triggers.get(tick, ()):
                    net.at(net.now + fault.offset_s, self._fault, fault)
        self._arm_world()

    def _arm_world(self) -> None:
        w = self.world
        if not w.alive:
            return
        due = self.world_protocol.timer()
        if due is not None and (w.timer_at is None or due < w.timer_at):
            w.timer_at = due
            self.net.local(w, max(due - self.net.now, 0.0), self._world_wake, due)

    def _world_wake(self, due: float) -> None:
        if self.world.timer_at != due:
            return
        self.world.timer_at = None
        self._world_timer()

    def _world_timer(self, _process=None) -> None:
        protocol = self.world_protocol
        due = protocol.timer()
        if due is not None and due <= self.net.now:
            self._world_effects(protocol.on_timer(self.net.now))
        else:
            self._arm_world()

    def _tokens_to_world(self, agents: list[int], alive: bool) -> None:
        protocol, now = self.world_protocol, self.net.now
        for i in agents:
            self._world_effects(protocol.on_liveliness(self.alive_keys[i], alive, now))
            if self.world_done:
                return

    def _intent_in(self, key: str, payload: bytes, agent: int, tick: int, era: int | None) -> None:
        """An intent reaches the world; ``era``: the world it was decided for (a world resumed
        under running agents replays tick numbers, so one of the world before may still come)."""
        if era != self.era:
            self.checker.stale_intent(self.era, agent, tick)
        self._world_effects(self.world_protocol.on_intent(key, payload, self.net.now))

    # The agents' processes.

    def _start_agent(self, i: int, resume: bool, episode: int | None = None) -> None:
        """Start agent ``i``'s process: afresh, or (``resume``) from its checkpoint's newest
        version, or that of ``episode`` (a resumed run's cut)."""
        if self.world_done or (resume and self.run_over):
            return
        a, net, c = self.agents[i], self.net, self.config
        a.incarnation += 1
        a.alive, a.stalled_until, a.waiting, a.timer_at = True, 0.0, [], None
        if i in self.checkpointed:
            brain, resumed = start_brain(i, c, checkpoint.checkpoint_path(self.checkpoint_dir, i),
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
            self.final_brains[i] = self.protocols[i].brain
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
                    brain = self.protocols[i].brain
                    checkpoint.save(checkpoint.checkpoint_path(self.checkpoint_dir, i), brain,
                                    effect.episode)
                    self.saved[i] = (effect.episode, checkpoint.fingerprint(brain))
                    self.saved_at[i][effect.episode] = self.saved[i][1]
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
        due = self.protocols[i].timer()
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
        protocol = self.protocols[i]
        due = protocol.timer()
        if due is not None and due <= self.net.now:
            self._agent_effects(i, protocol.on_timer(self.net.now))
        else:
            self._arm_agent(i)

    def _observation_in(self, i: int, era: int, tick: int, payload: bytes) -> None:
        self.checker.observation_in(i, era, tick)
        self._agent_effects(i, self.protocols[i].on_observation(payload, self.net.now))

    def _control_in(self, i: int, payload: bytes) -> None:
        self._agent_effects(i, self.protocols[i].on_control(payload, self.net.now))

    def _world_token_in(self, i: int, alive: bool) -> None:
        self._agent_effects(i, self.protocols[i].on_world(alive, self.net.now))

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
        self._agent_effects(i, self.protocols[i].on_query(number, parameters, self.net.now))

    def _answer_in(self, q: Query, payload: bytes) -> None:
        if q.open and self.agents[q.asker].incarnation == q.asker_incarnation:
            self._agent_effects(q.asker, self.protocols[q.asker].on_answer(q.ask, payload,
                                                                           self.net.now))

    def _refusal_in(self, q: Query) -> None:
        if q.open and self.agents[q.asker].incarnation == q.asker_incarnation:
            self._agent_effects(q.asker, self.protocols[q.asker].on_refusal(q.ask, self.net.now))

    def _ask_ended(self, q: Query) -> None:
        if q.open:
            q.open = False
            if self.agents[q.asker].incarnation == q.asker_incarnation:
                self._agent_effects(q.asker, self.protocols[q.asker].on_ask_end(q.ask,
                                                                                self.net.now))

    # Faults.

    def _fault(self, fault: Fault) -> None:
        net, kind = self.net, fault.kind
        if kind in WINDOWS:
            setattr(net, kind, fault.p)
            net.reorder_s = REORDER_S
            net.at(net.now + fault.duration_s, setattr, net, kind, 0.0)
        elif kind == "partition":
            net.cut = fault.group
            net.at(net.now + fault.duration_s, self._heal, fault.group)
        elif kind == "stall":
            process = self.processes[fault.target]
            if not process.alive:
                return
            resumed = self._world_timer if process is self.world else self._agent_resumed
            net.stall(process, fault.duration_s, resumed)
        elif kind == "kill-all":
            if self.world_done:
                return
            self._kill_all()
            net.at(net.now + fault.duration_s, self._resume_all)
        elif kind == FORGE:
            i = int(fault.target.split("-")[1])
            if not self.agents[i].alive:
                return
            self.forging[i] = self.agents[i].incarnation
        elif fault.target == "world":
            if not self.world.alive or self.world_done:
                return
            self._crash_world()
            net.at(net.now + fault.duration_s, self._in_generation, self.generation,
                   self._restart_world)
        else:
            i = int(fault.target.split("-")[1])
            if not self.agents[i].alive:
                return
            self._crash_agent(i)
            if not self.keep_all:  # a schedule crashes an agent once: nobody reads later ones
                self.saving.discard(i)
            net.at(net.now + fault.duration_s, self._in_generation, self.generation,
                   self._start_agent, i, True)
        self.fired.append(kind)

    def _in_generation(self, generation: int, restart, *args) -> None:
        """A supervisor's restart, unless everyone was killed since (its launcher with them)."""
        if generation == self.generation:
            restart(*args)

    def _kill_all(self) -> None:
        """Every process dies at once, the launcher too: nothing restarts them."""
        self.generation += 1
        if self.world.alive:
            self._crash_world()
        for i, a in enumerate(self.agents):
            if a.alive:
                self._crash_agent(i)
        self.writer.close()

    def _resume_all(self) -> None:
        """``launch/swarm.py --resume``: from the cut of the run's files, everyone again."""
        everyone = list(range(self.n))
        _, start = resume_point(self.disk, everyone, world=True)
        rewind(self.disk, start)
        del self.rows[start.episode:]
        self.checker.rewound(start.cut)  # a lagging agent goes on from its newest
        self.writer = EpisodeWriter(self.disk / EPISODES_FILE, sync=False)
        self.run_over = False
        if start.episode >= self.config.episodes:  # every row was written: nothing to play
            for i in everyone:  # what the agents end with is what they checkpointed last
                self.final_brains[i] = start_brain(
                    i, self.config, checkpoint.checkpoint_path(self.checkpoint_dir, i), True)[0]
            self.completed = self.world_done = True
            self.net.halted = True
            return
        self._start_world(start.episode, start.tick, shared_table(self.disk, self.config, start))
        for i in everyone:
            self.net.at(self.net.now + START_SPREAD_S * self.net.rng.random(), self._start_agent,
                        i, start.cut >= 0 or not start.exact, start.checkpoint_episode)

    def _heal(self, group: frozenset) -> None:
        if self.net.cut is group:
            self.net.cut = None

    def _agent_resumed(self, process: Process) -> None:
        self._agent_timer(self.agents.index(process))


def run_schedule(schedule: Schedule, scratch: Path | None = None,
                 fingerprints: bool = False) -> Outcome:
    """Run one schedule; ``scratch``: a directory under which the files of a run that crashes
    an agent or kills everyone are kept while it runs (a fresh directory of their own, removed
    after)."""
    if not (schedule.crashing_agents or schedule.kills_all):
        return SimSwarm(schedule).run(fingerprints)
    with tempfile.TemporaryDirectory(prefix="nnql-sim-", dir=scratch) as disk:
        return SimSwarm(schedule, Path(disk)).run(fingerprints)
