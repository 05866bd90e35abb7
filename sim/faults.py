"""A fault schedule's faults as they strike the simulated swarm: windows of drops, duplicates and
reordering, partitions, stalls, crashes and restarts, forged records, and every process killed at
once and the run continued as ``launch/swarm.py --resume`` continues it. A part of
``sim.distributed.SimSwarm``, whose state it shares."""

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.restore import start_brain
from nnql_swarm.sim.agent_processes import START_SPREAD_S
from nnql_swarm.sim.network import Process
from nnql_swarm.sim.schedule import FORGE, WINDOWS, Fault
from nnql_swarm.sim.swarm_state import SwarmState
from nnql_swarm.transport.runfiles import EPISODES_FILE
from nnql_swarm.sim.resume import resume_point, rewind, shared_table
from nnql_swarm.world.metrics import EpisodeWriter

REORDER_S = 0.005
"""How long a reordered message is held back at most."""


class Faults(SwarmState):
    """The faults' side of :class:`~sim.distributed.SimSwarm`."""

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
        assert self.writer is not None, "a run killed whole writes its rows"
        self.writer.close()

    def _resume_all(self) -> None:
        """``launch/swarm.py --resume``: from the cut of the run's files, everyone again."""
        everyone = list(range(self.n))
        disk = self._disk()
        _, start = resume_point(disk, everyone, world=True)
        rewind(disk, start)
        del self.rows[start.episode:]
        self.checker.rewound(start.cut)  # a lagging agent goes on from its newest
        self.writer = EpisodeWriter(disk / EPISODES_FILE, sync=False)
        self.run_over = False
        if start.episode >= self.config.episodes:  # every row was written: nothing to play
            for i in everyone:  # what the agents end with is what they checkpointed last
                self.final_brains[i] = start_brain(
                    i, self.config, agent_checkpoint.checkpoint_path(self._checkpoints(), i), True)[0]
            self.completed = self.world_done = True
            self.net.halted = True
            return
        self._start_world(start.episode, start.tick, shared_table(disk, self.config, start))
        for i in everyone:
            self.net.at(self.net.now + START_SPREAD_S * self.net.rng.random(), self._start_agent,
                        i, start.cut >= 0 or not start.exact, start.checkpoint_episode)

    def _heal(self, group: frozenset) -> None:
        if self.net.cut is group:
            self.net.cut = None

    def _agent_resumed(self, process: Process) -> None:
        self._agent_timer(self.agents.index(process))
