"""The swarm world, pure: positions, goals, the lockstep tick, observations out, intents in.

One tick: :meth:`SwarmWorld.observations` gives every agent its observation; the agents answer
with an action each (``None`` for an agent that missed the deadline: it stays, and the miss is
counted); :meth:`SwarmWorld.apply` moves everyone at once by the rules of ``world.rules`` and
scores the tick. Where the agents share one table, their intents also carry their learning
records of the tick: the world applies them to its copy (``world.shared_table``), and the next
observations hand everyone the entries they changed.

Each episode ends with one extra *end tick*: every agent is told ``episode_end`` (with the rewards
of its last action), finishes its learning, checkpoints and answers STAY; nothing moves. An agent
that reaches its goal is *arrived*: it stays on its goal, keeps answering STAY and is still an
obstacle to the others. The episode ends when every agent has arrived or after ``max_steps``.
Where an arrived agent takes no part in the negotiation (``SwarmConfig.quiet_settled``: the
``meet`` rule, or agents that do not negotiate), it is *settled* from the tick after its first
arrived observation (which finished its learning) until the end tick
(:attr:`SwarmWorld.settled`): it stays, the world needs no intent from it (``world.world_machine``),
and it is *quiet*: :meth:`observations_by_rank` sends it nothing, keeping the shared table's entries it did not
hear of. Its next observation (at the end tick, or once :data:`QUIET_CATCH_UP` entries are
waiting, which then says ``settled``) brings their current values, so that its copy is the
world's again before it checkpoints or decides.

The world keeps its state in the rules' buffers and plays a tick with ``world.step.play_step``
(settled first, under ``--arbitration pibt``, by ``world.arbiter``), the very functions the swarm
simulator runs compiled: in the world process, which runs the kernel uncompiled, through their
form compiled ahead of time where it is built (``world.rules_ahead``; the buffers are arrays
then), else in plain Python (lists). The buffers hold every body: the agents, then the run's
walls (``protocol.walls``), which always stay and which nobody is told about (every process
knows them).
"""

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from itertools import compress

import numpy as np

from nnql_swarm.protocol.actions import STAY, VIEW_RADIUS
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.learning.ahead import PLAIN
from nnql_swarm.learning.tables import buffer_makers
from nnql_swarm.protocol.jit import COMPILED, Buffer, python_values
from nnql_swarm.protocol.messages import (
    CELL_TYPE, MAX_AGENTS, MAX_SYNC_GROUPS, NEIGHBOUR_ITEMS, WORLD_SENDER, Observation, pack_ids,
)
from nnql_swarm.protocol.ranks import priority_rank
from nnql_swarm.world.rules_ahead import RULES
from nnql_swarm.world.rules import (
    FIELD_COLUMNS, ROW_GOALS, TASK_COLUMNS, task_columns, ROW_AGENT_STEPS, ROW_ARRIVED, ROW_COLLISIONS, ROW_FLOATS, ROW_INTS, ROW_REWARD,
    ROW_STEPS, Cell, field_columns, field_costs,
)
from nnql_swarm.world.arbiter import Arbiter
from nnql_swarm.world.step import MOVE_EVERYONE, MOVE_FIELDS, MOVE_SHARED, MOVE_SWAPPED
from nnql_swarm.world.tasks import goal_sequences
from nnql_swarm.world.scenario import swarm_episode
from nnql_swarm.world.sight import ITEM_BYTES
from nnql_swarm.world.shared_table import SharedState, SharedTable, Updates
from nnql_swarm.world.unheard import UnheardEntries

SYNC_ENTRIES = MAX_SYNC_GROUPS * MAX_AGENTS
"""Table entries sent with each observation of an agent being resynchronised (2,048: about
25 KB; the default preset's 6,615 entries take 4 ticks)."""

QUIET_CATCH_UP = 512
"""Entries of the shared table a quiet agent may not have heard of before it is sent an
observation again, with their current values (about 6 KB; at the end tick every quiet agent's
come at once, and through a router one link carries them all)."""

EPISODE_FIELDS = (
    "episode", "steps", "collisions", "missed_intents", "reward_sum", "arrived", "shortest_sum",
    "agent_steps", "end_tick",
) + FIELD_COLUMNS + TASK_COLUMNS
"""The deterministic columns of ``episodes.csv``, one row per episode (the last, the field's
metrics: ``world.rules.field_columns``)."""


@dataclass(frozen=True)
class TickReport:
    """What one tick did: the actions applied, who collided, the finished episode's row, if any;
    under ``--arbitration pibt`` each agent's first choice (``wanted``: where it differs from
    the action applied, the arbitration refused it); in a lifelong run each agent's goal after
    the tick (``goals``) and who reached one (``reached``)."""

    tick: int
    episode: int
    moved: bool
    actions: tuple[int, ...]
    collided: tuple[int, ...]
    missed: tuple[int, ...]
    violations: tuple[str, ...]
    episode_row: dict | None
    table: SharedState | None = None  # at an episode's end, if shared
    records: dict | None = None  # the learning records applied, by agent, if shared
    wanted: tuple[int, ...] = ()
    goals: tuple[Cell, ...] = ()
    reached: tuple[int, ...] = ()


class SwarmWorld:
    """The lockstep world of a swarm run (every agent learns, each has its own goal)."""

    incarnation = 0
    """Which start of the run's world this is (``Observation.world``)."""

    def __init__(self, config: SwarmConfig, first_episode: int = 0, first_tick: int = 0,
                 table: SharedState | None = None) -> None:
        """A world at the start of ``first_episode`` (``--resume`` starts after the last row,
        with the shared ``table`` of its checkpoint, where the agents share one: its end tick's
        records are applied as that tick applied them, and the first observations carry what
        they changed, as they did in the run that wrote the checkpoint)."""
        self.config = config
        self.tick = first_tick
        self.finished = False
        self.violations = 0
        n, bodies = config.n_agents, config.n_bodies
        walls = config.walls()
        self._wall_x, self._wall_y = walls[:, 0].tolist(), walls[:, 1].tolist()
        self._step, how = RULES.compiled("world_move")  # world.step.world_move
        ints, floats, flags = self._makers = buffer_makers(how != PLAIN)
        self._x, self._y = ints([0] * bodies), ints([0] * bodies)
        self._goal_x, self._goal_y = ints([-1] * bodies), ints([-1] * bodies)
        self._learns = flags([True] * n + [False] * (bodies - n))
        self._before_x, self._before_y = ints([0] * bodies), ints([0] * bodies)
        self._occupancy = ints([0] * (config.width * config.height))
        self._blocked = flags([False] * bodies)
        self._reached = flags([False] * n)  # who reached a goal this step (lifelong runs)
        self._moved = ints([0] * MOVE_FIELDS)
        self._tasks, self._next_goal = ints([]), ints([])  # a lifelong run's, per episode
        self._no_ranks = ints([])  # the step's ranks where nobody announces an order
        self._stays = [STAY] * (bodies - n)
        self.table = SharedTable(config) if config.shared else None
        self.arbiter = Arbiter(config) if config.arbitration == "pibt" else None
        self._updates: Updates = ()
        if table is not None and self.table is not None:
            self.table.restore(table.q_ds, table.q_ca)
            self._updates = self.table.apply({agent: (integers, rewards)
                                              for agent, integers, rewards in table.records})
        self._syncing: dict[int, int] = {}  # agent -> the first table entry it is sent next
        self._unheard = UnheardEntries(  # what each quiet agent missed
            QUIET_CATCH_UP, 0 if self.table is None else self.table.entries)
        self._sync_from_next: set[int] = set()  # resynchronised since the last tick closed
        # On a grid that fits in the egocentric window, everybody always sees everybody.
        self._sees_all = max(config.width, config.height) <= VIEW_RADIUS + 1
        self._pack_seen, how = RULES.compiled("pack_seen")  # world.sight.pack_seen
        pairs = n * (n - 1)  # the kernel's buffers: every agent may see every other
        self._seen: Buffer
        self._parked: Buffer
        self._seen_at: Buffer
        self._parked_at: Buffer
        self._seen_arrays = how != PLAIN
        if how == PLAIN:
            self._seen, self._parked = [0] * (NEIGHBOUR_ITEMS * pairs), [0] * pairs
            self._seen_at, self._parked_at = [0] * (n + 1), [0] * (n + 1)
        else:
            self._seen = np.zeros(NEIGHBOUR_ITEMS * pairs, dtype=CELL_TYPE)
            self._parked = np.zeros(pairs, dtype=CELL_TYPE)
            self._seen_at, self._parked_at = (np.zeros(n + 1, dtype=np.int64) for _ in range(2))
        self._start_episode(first_episode)

    @property
    def positions(self) -> np.ndarray:
        """Every agent's cell, ``(N, 2)``: a new array each time."""
        return np.array(self.cells, dtype=np.int64).reshape(-1, 2)

    @property
    def cells(self) -> tuple[Cell, ...]:
        """Every agent's cell as ``(x, y)``, by agent id."""
        n = self.config.n_agents
        return tuple(zip(python_values(self._x)[:n], python_values(self._y)[:n]))

    def sight(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
        """What this tick's observations show of the agents, as arrays by agent id: their cells'
        ``x`` and ``y``, and whether each has arrived (1) or not (0); and whether every agent
        sees every other (the grid fits in the view)."""
        n = self.config.n_agents
        x, y = (np.array(values[:n], dtype=np.int64) for values in (self._x, self._y))
        arrived = np.array(self._outcome[3][:n], dtype=np.int64)  # what _observation reads
        return x, y, arrived, self._sees_all

    @property
    def arrived_flags(self) -> tuple[bool, ...]:
        """Whether each agent has arrived, by agent id."""
        return tuple(python_values(self._arrived)[:self.config.n_agents])

    @property
    def arrived(self) -> np.ndarray:
        """Whether each agent has arrived, ``(N,)``: a new array each time."""
        return np.array(self.arrived_flags, dtype=bool)

    def _start_episode(self, episode: int) -> None:
        c = self.config
        scenario = swarm_episode(c.seed, episode, c.width, c.height, c.n_agents,
                                 c.obstacle_density, c.map_rows, c.scenario)
        ints, floats, flags = self._makers
        self.episode = episode
        self.step = 0
        self.goals = scenario.goals
        self.ending = False
        self.settled: frozenset[int] = frozenset()  # see the module docstring
        self._unheard.clear()
        n, bodies = c.n_agents, c.n_bodies
        self._x[:] = scenario.starts[:, 0].tolist() + self._wall_x
        self._y[:] = scenario.starts[:, 1].tolist() + self._wall_y
        self._goal_x[:n], self._goal_y[:n] = scenario.goals[:, 0].tolist(), scenario.goals[:, 1].tolist()
        self._goal_cells = [tuple(cell) for cell in scenario.goals.tolist()]
        self._arrived = flags([False] * bodies)
        self._arrival = ints([0] * bodies)
        self._r_ds = floats([0.0] * bodies)
        self._r_ca = floats([0.0] * bodies)
        self._collided = flags([False] * bodies)
        self._row = ints([0] * ROW_INTS)
        self._row_f = floats([0.0] * ROW_FLOATS)
        self._missed = 0
        self._shortest = int(scenario.shortest.sum())
        if self.arbiter is not None:
            self.arbiter.start_episode(scenario.shortest.tolist())
        if c.lifelong:
            walls = c.walls()
            self._tasks = ints(goal_sequences(c.seed, episode, c.width, c.height, walls,
                                              scenario.goals, c.max_steps,
                                              c.goal_lists).reshape(-1).tolist())
            self._next_goal = ints([0] * n)
        self._plain()

    def _plain(self) -> None:
        """The state as Python values, for the observations."""
        self._cells = self.cells
        self._outcome = (python_values(self._r_ds), python_values(self._r_ca),
                         python_values(self._collided), python_values(self._arrived))

    def observations(self) -> list[Observation]:
        """Every agent's observation for the current tick, indexed by agent id."""
        neighbours = self._neighbours()
        return [self._observation(i, neighbours(i)) for i in range(self.config.n_agents)]

    def observations_by_rank(self) -> Iterator[Observation]:
        """The observations to send, in rank order, each built only when the one before it is
        taken: the world sends the first to decide its observation before it builds the others'.
        Settled agents get none, but those being sent the table (see the module docstring)."""
        n, tick = self.config.n_agents, self.tick
        neighbours = self._neighbours()
        quiet = self.settled.difference(self._syncing)
        if quiet:
            self._unheard.log_tick(self._updates)
        for rank in range(n):
            agent = (rank + tick) % n  # the inverse of priority_rank
            if agent in quiet and self._unheard.quiet(agent):
                continue
            yield self._observation(agent, neighbours(agent))

    def _observation(self, i: int, seen: tuple[bytes, bytes]) -> Observation:
        """Agent ``i``'s observation; ``seen``: its neighbours and parked ones, packed."""
        c = self.config
        r_ds, r_ca, collided, arrived = self._outcome
        updates = self._updates
        unheard = self._unheard.pop(i)
        if unheard or i in self._syncing:
            table = self.table
            assert table is not None, "only a shared table leaves entries to send"
            if unheard:
                updates = table.current(unheard) + updates
            if i in self._syncing:
                updates += table.chunk(self._syncing[i], SYNC_ENTRIES)
        # Positional, in Observation's field order: keywords cost a fifth of this call.
        return Observation(c.run_id, self.tick, WORLD_SENDER, i, self.episode, self.step,
                           self._cells[i], self._goal_cells[i], seen[0],
                           priority_rank(i, self.tick, c.n_agents), r_ds[i], r_ca[i],
                           collided[i], arrived[i], self.ending, seen[1], updates,
                           i in self.settled, self.incarnation)

    def unsettle(self, agents: set[int]) -> None:
        """Make ``agents`` not settled at this tick: the world must hear from them (to send a
        restarted agent its table from its first intent on)."""
        self.settled = self.settled - agents

    def resync(self, agent: int) -> None:
        """Send ``agent`` the whole shared table, a slice with each of its next observations
        (``world.shared_table``): its copy may differ from the world's (it was restarted, or the
        world was). Nothing to do where every agent learns alone."""
        if self.table is not None:
            self._syncing[agent] = 0
            self._sync_from_next.add(agent)

    @property
    def syncing(self) -> tuple[int, ...]:
        """The agents still being sent the whole table."""
        return tuple(sorted(self._syncing))

    def _neighbours(self) -> Callable[[int], tuple[bytes, bytes]]:
        """Each agent's visible others ``(id, x, y)`` in id order, and the ids of those parked
        (arrived, as the observations show it, where arrived agents park), packed as the wire
        carries them, by agent id: every agent's at once (``world.sight.pack_seen``), in one
        ``bytes`` of each packing a tick, of which an agent's are slices."""
        n = self.config.n_agents
        seen, parked, seen_at, parked_at = self._seen, self._parked, self._seen_at, self._parked_at
        arrived = self._outcome[3]  # as the observations show it
        self._pack_seen(self._x, self._y, np.array(arrived, dtype=bool) if self._seen_arrays
                        else arrived, n, self._sees_all, not self.config.step_aside, seen,
                        parked, seen_at, parked_at)
        seen_at, parked_at = python_values(seen_at), python_values(parked_at)
        packed = pack_ids(seen[:seen_at[n] // ITEM_BYTES])
        if self.config.step_aside:  # arrived agents do not park
            return lambda i: (packed[seen_at[i]:seen_at[i + 1]], b"")
        parked_ids = pack_ids(parked[:parked_at[n] // ITEM_BYTES])
        return lambda i: (packed[seen_at[i]:seen_at[i + 1]],
                          parked_ids[parked_at[i]:parked_at[i + 1]])

    def apply(self, actions: list[int | None], learned: dict | None = None,
              orders: list[tuple[int, ...] | None] | None = None) -> TickReport:
        """Apply every agent's action for this tick (``None``: missed, counted, stays; under
        ``--arbitration pibt`` the agents' ``orders``, settled by ``world.arbiter``);
        ``learned``: the accepted learning records that came with the intents, by agent (the
        end tick's report holds the shared table from before they are applied, what the agents
        checkpointed, with those records: what the next episode starts from)."""
        missed = tuple(i for i, a in enumerate(actions) if a is None)
        self._missed += len(missed)
        records = None if self.table is None else learned or {}
        report = self._end_tick(missed, learned or {}, records) if self.ending else \
            self._move(actions, missed, records, orders)
        if self.table is not None:
            assert records is not None
            self._updates = self.table.apply(records)
            for agent, start in list(self._syncing.items()):
                if agent in self._sync_from_next:  # its first slice goes with the next tick
                    continue
                if start + SYNC_ENTRIES >= self.table.entries:
                    del self._syncing[agent]
                else:
                    self._syncing[agent] = start + SYNC_ENTRIES
            self._sync_from_next.clear()
        return report

    def episode_row(self) -> dict:
        """The running episode's row of ``episodes.csv`` (its deterministic columns)."""
        row, reward = python_values(self._row), python_values(self._row_f)[ROW_REWARD]
        n = self.config.n_agents
        bodies: tuple = (self._x, self._y, self._goal_x, self._goal_y, self._arrival)
        if not COMPILED:  # plain Python reads lists faster than arrays; numba reads arrays
            bodies = tuple(python_values(b) for b in bodies)
        on_goal, soc, makespan = field_costs(*bodies, n, row[ROW_STEPS])
        return {"episode": self.episode, "steps": row[ROW_STEPS],
                "collisions": row[ROW_COLLISIONS], "missed_intents": self._missed,
                "reward_sum": reward, "arrived": row[ROW_ARRIVED],
                "shortest_sum": self._shortest, "agent_steps": row[ROW_AGENT_STEPS],
                "end_tick": self.tick, **field_columns(on_goal, soc, makespan, n),
                **task_columns(row[ROW_GOALS], row[ROW_STEPS])}

    def _end_tick(self, missed: tuple[int, ...], learned: dict,
                  records: dict | None) -> TickReport:
        """The episode's end tick: nothing moves; the row is final; the next episode starts."""
        c = self.config
        stays = (STAY,) * c.n_agents
        report = TickReport(self.tick, self.episode, False, stays, (), missed, (),
                            self.episode_row(),
                            None if self.table is None else self.table.state(learned), records)
        self.tick += 1
        if self.episode + 1 >= c.episodes:
            self.finished = True
        else:
            self._start_episode(self.episode + 1)
        return report

    def _move(self, actions: list[int | None], missed: tuple[int, ...], records: dict | None,
              orders: list[tuple[int, ...] | None] | None) -> TickReport:
        """A step of the episode: everyone moves at once; rewards, arrivals and the row
        (``world.step.world_move``)."""
        c = self.config
        n = c.n_agents
        arrived_before = self._outcome[3]  # as this tick's observations showed it
        chosen = self._makers[0]([STAY if a is None else a for a in actions] + self._stays)
        arbiter, ranks = self.arbiter, self._no_ranks
        if arbiter is not None:  # the moves of priority inheritance into chosen
            told = [None if a is None else o or (a,)
                    for a, o in zip(actions, orders or [()] * len(actions))]
            arbiter.settle(self._x, self._y, self._goal_x, self._goal_y, self._arrived, told,
                           chosen, self.step)
            ranks = arbiter.ranks
        moved = self._moved
        self._step(c.n_bodies, c.width, c.height, c.count_swaps, c.step_aside, c.goal_reward,
                   c.stay_reward, self._x, self._y, self._goal_x, self._goal_y, self._learns,
                   self._arrived, self._arrival, chosen, self._before_x, self._before_y,
                   self._collided, self._r_ds, self._r_ca, self._occupancy, self._blocked,
                   self._row, self._row_f, n, arbiter is not None, ranks, c.lifelong,
                   self._tasks, c.max_steps, self._next_goal, self._reached, moved)
        reached: list = []
        if c.lifelong:  # each agent that reached its goal has the next one at once
            reached = python_values(self._reached)
            self._goal_cells = list(zip(python_values(self._goal_x)[:n],
                                        python_values(self._goal_y)[:n]))
        violations = self._check(moved[MOVE_SHARED], moved[MOVE_SWAPPED])
        self._plain()
        if c.lifelong:  # the observations say who reached a goal: its last step was terminal
            self._outcome = (*self._outcome[:3], reached)
        self.step += 1
        self.ending = (moved[MOVE_EVERYONE] != 0 and not c.lifelong) or self.step >= c.max_steps
        collided = self._outcome[2]
        self.settled = (frozenset() if self.ending or not c.quiet_settled
                        else frozenset(compress(range(n), arrived_before)))
        wanted = () if arbiter is None else arbiter.first_choices()
        report = TickReport(self.tick, self.episode, True, tuple(python_values(chosen)[:n]),
                            tuple(compress(range(n), collided)), missed,
                            violations, None, None, records, wanted,
                            tuple(self._goal_cells) if c.lifelong else (),
                            tuple(compress(range(n), reached)) if c.lifelong else ())
        self.tick += 1
        return report

    def _check(self, shared: int, swapped: int) -> tuple[str, ...]:
        """The invariants every tick must hold, as the step counted them: no shared cell, no
        swap-through (if counted)."""
        problems = []
        if shared:
            problems.append("two agents share a cell")
        if swapped:
            problems.append("an agent swapped through another agent")
        self.violations += len(problems)
        return tuple(problems)

