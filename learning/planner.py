"""An agent's plan of each observation: whom it waits for, asks, answers, knows to stay and
streams with (:class:`Plan`), worked out by ``learning.plan.agent_plan`` in one call,
compiled ahead of time where it is built (``learning.ahead``). The agent plans its ticks with it
(``agent.negotiation`` says what each part means to the negotiation); the world reads the same
plan of an observation when it checks the learning record decided on it (``world.records``)."""

from typing import NamedTuple

import numpy as np

from nnql_swarm.learning import ahead
from nnql_swarm.learning.plan import (
    P_ANSWERED, P_ASKS, P_AWAITED, P_FITS, P_STAYING, P_STREAMED, PLAN_PARTS, SCRATCH,
)
from nnql_swarm.protocol.actions import VIEW_RADIUS
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.jit import Buffer, python_values
from nnql_swarm.protocol.messages import CELL_TYPE, NEIGHBOUR_ITEMS, Observation


STREAM_MARGIN = 4
"""How far beyond the interaction radius an agent keeps standing queries open (cells, Chebyshev):
two agents close in on each other by at most two cells a tick, so one that comes this near is
streamed a tick or two before it can be asked."""


def plans_are_known(config: SwarmConfig) -> bool:
    """Whether a decider sees every agent that an agent within its reach waits for, and so can
    tell whose plan (:attr:`Plan.asks`) asks it: the grid fits in the view, or twice the
    interaction radius does."""
    return (max(config.width, config.height) <= VIEW_RADIUS + 1
            or 2 * config.interaction_radius <= VIEW_RADIUS)


def unpack_seen(obs: Observation, arrays: bool) -> tuple:
    """An observation's neighbours ``(id, x, y)`` and parked ids as the kernels read them
    (``learning.plan.unpack_seen_into``): fresh arrays ``(k, 3)`` and ``(p,)`` where they are
    compiled (``arrays``), else lists."""
    seen, k, p = _packed(obs, arrays)
    nb: Buffer
    parked: Buffer
    if arrays:
        nb, parked = np.empty((k, NEIGHBOUR_ITEMS), dtype=np.int64), np.empty(p, dtype=np.int64)
    else:
        nb, parked = [[0] * NEIGHBOUR_ITEMS for _ in range(k)], [0] * p
    ahead.KERNELS.compiled("unpack_seen_into")[0](seen, k, p, nb, parked)
    return nb, parked


def _packed(obs: Observation, arrays: bool) -> tuple:
    """An observation's two packings one after the other as their integers (an array, or a
    list where the kernels are not compiled), and how many neighbours and parked ids they
    hold."""
    seen = np.frombuffer(obs.neighbours + obs.parked, CELL_TYPE)
    k = len(obs.neighbours) // _NEIGHBOUR_BYTES
    return (seen if arrays else seen.tolist()), k, len(seen) - NEIGHBOUR_ITEMS * k


_NEIGHBOUR_BYTES = NEIGHBOUR_ITEMS * CELL_TYPE.itemsize


class Plan(NamedTuple):
    """What an agent does about its neighbours at an observation (``learning.plan``)."""

    awaited: list[int]
    """Whose intents it waits for (``learning.plan.awaited_into``), in id order."""
    asks: list[int]
    """Whom of them it asks, the lowest-ranked first: the fewest whose answers, with what they
    relay, bring every awaited intent."""
    staying: list[int]
    """Under ``meet``, the parked neighbours whose intents, STAY, it knows without waiting."""
    answered: list[int]
    """Whom it answers through their standing queries at this tick, the next in rank first:
    those whose plan asks it (:func:`plans_are_known`), or else every agent that waits for
    it."""
    near: list[int]
    """The agents it keeps standing queries open on, and whose standing queries on it it keeps:
    those within the interaction radius and :data:`STREAM_MARGIN` (at most the view), the only
    ones it can soon ask or be asked by, in id order."""
    cells: object
    """The observation's neighbours ``(id, x, y)`` as the kernels read them: an array ``(k, 3)``
    where they are compiled, else lists (``learning.rows.NeighbourRows`` reads them too). Like
    :attr:`parked`, the planner's own buffer until it plans again: :meth:`kept` copies them."""
    parked: object
    """Its parked ids, likewise."""

    def kept(self) -> "Plan":
        """This plan with its own copies of :attr:`cells` and :attr:`parked`, to be read after
        the planner plans another observation."""
        cells, parked = self.cells, self.parked
        if isinstance(cells, np.ndarray) and isinstance(parked, np.ndarray):
            return self._replace(cells=cells.copy(), parked=parked.copy())
        assert isinstance(cells, list) and isinstance(parked, list), "arrays, else lists"
        return self._replace(cells=[list(row) for row in cells], parked=list(parked))


class Planner:
    """One agent's :class:`Plan` of each observation: ``learning.plan.agent_plan`` in one call,
    compiled ahead of time where it is built (``learning.ahead``), over buffers kept."""

    def __init__(self, config: SwarmConfig) -> None:
        self._plan, how = ahead.KERNELS.compiled("agent_plan")
        self._arrays = how != ahead.PLAIN
        size = config.n_agents + 1  # every neighbour and the agent
        self._scratch: np.ndarray | list[list[int]]  # the kernel's buffers (learning.plan)
        self._out: np.ndarray | list[list[int]]
        self._counts: np.ndarray | list[int]
        self._nb: np.ndarray | list[list[int]]  # the observation's neighbours, and parked ids
        self._parked: np.ndarray | list[int]
        self._flat: np.ndarray | list[int]  # every part of the plan, one after the other
        if self._arrays:
            self._scratch = np.zeros((SCRATCH, size), dtype=np.int64)
            self._out = np.zeros((PLAN_PARTS, size), dtype=np.int64)
            self._counts = np.zeros(PLAN_PARTS + 1, dtype=np.int64)
            self._nb = np.zeros((size, NEIGHBOUR_ITEMS), dtype=np.int64)
            self._parked = np.zeros(size, dtype=np.int64)
            self._flat = np.zeros(PLAN_PARTS * size, dtype=np.int64)
        else:
            self._scratch = [[0] * size for _ in range(SCRATCH)]
            self._out = [[0] * size for _ in range(PLAN_PARTS)]
            self._counts = [0] * (PLAN_PARTS + 1)
            self._nb = [[0] * NEIGHBOUR_ITEMS for _ in range(size)]
            self._parked = [0] * size
            self._flat = [0] * (PLAN_PARTS * size)
        self._negotiates = config.algo in NEGOTIATING_ALGOS
        self._plans_known = plans_are_known(config)
        self._reach = min(VIEW_RADIUS, config.interaction_radius + STREAM_MARGIN)
        self._n, self._width, self._height = config.n_agents, config.width, config.height
        self._radius, self._meet = config.interaction_radius, config.meet_only
        self._parks_still = not config.step_aside  # an arrived agent waits for nobody

    def __call__(self, obs: Observation) -> Plan | None:
        """The plan of ``obs``; None where it does not fit the run: more neighbours than its
        agents, a neighbour twice or the agent itself, a cell off its grid, an agent or rank it
        has not (the kernels, compiled, would read past their buffers). Its :attr:`Plan.cells`
        and :attr:`Plan.parked` are this planner's until its next call (:meth:`Plan.kept`)."""
        seen, k, p = _packed(obs, self._arrays)
        n, (x, y), (gx, gy) = self._n, obs.position, obs.goal
        width, height, meet = self._width, self._height, self._meet
        if (k >= n or p >= n or obs.rank >= n or x >= width or gx >= width or y >= height
                or gy >= height):
            return None
        counts, flat = self._counts, self._flat
        total = self._plan(seen, k, p, obs.agent, x, y, obs.rank, obs.tick, n, width, height,
                           self._radius, meet, obs.arrived and self._parks_still,
                           self._negotiates and not obs.episode_end, meet and p > 0,
                           self._plans_known, self._reach, self._nb, self._parked,
                           self._scratch, self._out, counts, flat)
        sizes = python_values(counts)
        if not sizes[P_FITS]:
            return None
        ids = python_values(flat[:total]) if total else []
        parts, start = [], 0
        for size in sizes[:PLAN_PARTS]:
            parts.append(ids[start:start + size])
            start += size
        return Plan(parts[P_AWAITED], parts[P_ASKS], parts[P_STAYING], parts[P_ANSWERED],
                    parts[P_STREAMED], self._nb[:k], self._parked[:p])
