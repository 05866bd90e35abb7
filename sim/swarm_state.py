"""The state of one run of the simulated swarm, which its parts share: the world's process
(``sim.world_process``), the agents' (``sim.agent_processes``) and the faults (``sim.faults``)
act on it, and call each other through the methods declared here; ``sim.distributed.SimSwarm``
joins them and runs them."""

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.agent_machine import AgentMachine
from nnql_swarm.protocol import keys
from nnql_swarm.sim.checks import Checker
from nnql_swarm.sim.network import Network, Process
from nnql_swarm.sim.schedule import Fault, Schedule, schedule_rng
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.world_machine import WorldMachine
from nnql_swarm.world.shared_table import SharedState


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


class SwarmState(ABC):
    """One run's processes, machines, files and checks (see the module docstring)."""

    world_protocol: WorldMachine  # the world's machine, from the run's start

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
            (self._disk() / CONFIG_FILE).write_text(c.to_json() + "\n")
        self.writer = EpisodeWriter(self._disk() / EPISODES_FILE, sync=False) \
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

    def _disk(self) -> Path:
        """The run's directory, which a run that writes files has."""
        assert self.disk is not None, "this run writes no files"
        return self.disk

    def _checkpoints(self) -> Path:
        """Where the agents' checkpoints go, in a run that writes them."""
        assert self.checkpoint_dir is not None, "this run writes no checkpoints"
        return self.checkpoint_dir

    def _machine(self, i: int) -> AgentMachine:
        """Agent ``i``'s protocol machine, which a running agent has."""
        protocol = self.protocols[i]
        assert protocol is not None, "the agent is not running"
        return protocol

    def _all_gone(self) -> None:
        if self.world_done and not any(a.alive for a in self.agents):
            self.net.halted = True

    # The world's process.

    @abstractmethod
    def _start_world(self, first_episode: int, first_tick: int,
                     table: SharedState | None = None) -> None: ...

    @abstractmethod
    def _crash_world(self) -> None: ...

    @abstractmethod
    def _restart_world(self) -> None: ...

    @abstractmethod
    def _world_timer(self, _process: Process | None = None) -> None: ...

    @abstractmethod
    def _tokens_to_world(self, agents: list[int], alive: bool) -> None: ...

    @abstractmethod
    def _intent_in(self, key: str, payload: bytes, agent: int, tick: int,
                   era: int | None) -> None: ...

    # The agents' processes.

    @abstractmethod
    def _start_agent(self, i: int, resume: bool, episode: int | None = None) -> None: ...

    @abstractmethod
    def _crash_agent(self, i: int) -> None: ...

    @abstractmethod
    def _agent_timer(self, i: int) -> None: ...

    @abstractmethod
    def _observation_in(self, i: int, era: int, tick: int, payload: bytes) -> None: ...

    @abstractmethod
    def _control_in(self, i: int, payload: bytes) -> None: ...

    @abstractmethod
    def _world_token_in(self, i: int, alive: bool) -> None: ...

    # The faults.

    @abstractmethod
    def _fault(self, fault: Fault) -> None: ...
