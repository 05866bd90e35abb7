"""The world's arbitration by priority inheritance (``--arbitration pibt``), pure: the agents'
announced orders in, every agent's move out, by ``world.pibt.plan``, the very function the swarm
simulator (``sim.episode``) runs compiled.

An agent's order (``protocol.messages.Intent.order``) lists its moves by preference; a missed
intent offers only STAY (the agent stays unless pushed, and cannot be pushed: it is not there to
be told). The arbitration's priorities carry over from step to step within an episode (PIBT's:
:meth:`Arbiter.start_episode` sets them from the agents' shortest paths, as the simulator does).

In the world process ``plan`` runs compiled ahead of time where it is built
(``world.rules_ahead``, as the world's step does: its buffers are arrays then), else in plain
Python (lists).
"""

from nnql_swarm.learning.ahead import PLAIN
from nnql_swarm.learning.tables import buffer_makers
from nnql_swarm.protocol.jit import Buffer, python_values
from nnql_swarm.protocol.actions import N_ACTIONS, STAY
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.world.pibt import UNWANTED
from nnql_swarm.world.rules_ahead import RULES


class Arbiter:
    """One run's arbitration state: ``plan``'s scratch, the priorities, the orders' ranks; its
    buffers are of the kind the world's step reads (numpy arrays where ``plan`` is compiled, else
    lists)."""

    def __init__(self, config: SwarmConfig) -> None:
        self.config = config
        self._plan, how = RULES.compiled("pibt_plan")  # world.pibt.plan
        ints, _, flags = buffer_makers(how != PLAIN)
        n, bodies = config.n_agents, config.n_bodies
        cells = config.width * config.height
        size = max(cells, bodies)

        def slots() -> Buffer:
            return ints([0] * size)

        self.priority, self.closest = slots(), slots()
        self._distances = ints([0] * (n * cells))
        self._occupant, self._reserved, self._order, self._blocked = (slots(), slots(), slots(),
                                                                      slots())
        self._queue, self._stack, self._tried, self._probe = slots(), slots(), slots(), slots()
        self._swapper, self._first = slots(), slots()
        self._decided = flags([False] * bodies)
        self._goal_of = ints([-1] * n)  # the goal each agent's distances are for
        self._unwanted = [UNWANTED] * (bodies * N_ACTIONS)
        self.ranks = ints(self._unwanted)
        """Each body's rank of each move this step (0: its first choice)."""

    def first_choices(self) -> tuple[int, ...]:
        """Each agent's first choice of the step settled last (STAY for a missed intent)."""
        ranks = python_values(self.ranks)
        return tuple(next(a for a in range(N_ACTIONS) if ranks[i * N_ACTIONS + a] == 0)
                     for i in range(self.config.n_agents))

    def start_episode(self, shortest: list[int]) -> None:
        """PIBT's first order: the agent farthest from its goal first; none has been nearer."""
        for i, length in enumerate(shortest):
            self.priority[i] = length
            self.closest[i] = length + 1

    def settle(self, x: Buffer, y: Buffer, goal_x: Buffer, goal_y: Buffer, arrived: Buffer,
               orders: list[tuple[int, ...] | None], actions: Buffer, step: int) -> None:
        """Every agent's move this step into ``actions`` (the bodies' buffer; walls stay), from
        the agents' ``orders`` (None: missed)."""
        c, ranks = self.config, self.ranks
        ranks[:] = self._unwanted
        for i, order in enumerate(orders):
            base = i * N_ACTIONS
            for rank, a in enumerate(order or (STAY,)):
                ranks[base + a] = rank
        self._plan(x, y, goal_x, goal_y, arrived, c.n_bodies, c.n_agents, c.width, c.height,
                   c.step_aside, self.priority, self.closest, actions, self._distances,
                   self._occupant, self._reserved, self._decided, self._order, self._blocked,
                   self._queue, self._stack, self._tried, self._probe, self._swapper,
                   self._first, step, self._goal_of, True, ranks)
