"""The world's process on the simulated network: its protocol machine started, crashed and
restarted as ``--resume`` restarts it, and its effects carried to the agents, the rows and the
checks. A part of ``sim.distributed.SimSwarm``, whose state it shares."""

from nnql_swarm.protocol.effects import Finished, SendControl, SendObservations, TickClosed, WriteRow
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.sim.network import Process
from nnql_swarm.sim.swarm_state import SwarmState
from nnql_swarm.world.world_machine import WorldMachine
from nnql_swarm.world.shared_table import SharedState


class WorldProcess(SwarmState):
    """The world's side of :class:`~sim.distributed.SimSwarm`."""

    def _start_world(self, first_episode: int, first_tick: int,
                     table: SharedState | None = None) -> None:
        w, net = self.world, self.net
        w.incarnation += 1
        w.alive, w.stalled_until, w.waiting, w.timer_at = True, 0.0, [], None
        self.era += 1
        self.world_protocol = WorldMachine(self.config, net.now, first_episode, first_tick,
                                            table=table, incarnation=w.incarnation)
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
                    world_checkpoint.save(world_checkpoint.table_path(self._disk()), effect.table,
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

    def _world_timer(self, _process: Process | None = None) -> None:
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
