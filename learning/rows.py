"""The learner's neighbour rows of an observation (``learning.fields.NB_*``):
``learning.neighbours.neighbour_rows_into`` in one call, compiled ahead of time where it is built
(``learning.ahead``), over buffers kept. The agent decides with them: its decision's kernel reads
them over this class's buffers (``agent.brain``, ``learning.decision.agent_decision``), and so
does an arrived agent that makes way; the world reads the same when it checks a learning record
the slow way (``world.records``; its usual way reads them inside
``learning.expected.expected_record``)."""

import numpy as np

from nnql_swarm.learning import ahead
from nnql_swarm.learning.fields import NB_FIELDS, reach
from nnql_swarm.learning.known_map import check_cell_order
from nnql_swarm.learning.planner import unpack_seen
from nnql_swarm.protocol.actions import VIEW_RADIUS
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.messages import Observation


class NeighbourRows:
    """One learner's neighbour rows of each observation: what an agent reads its neighbours as,
    and what the world reads them as when it checks the agent's learning record."""

    def __init__(self, config: SwarmConfig) -> None:
        self.config = config
        self._rows, how = ahead.KERNELS.compiled("neighbour_rows_into")
        self.arrays = how != ahead.PLAIN
        """Whether the rows are numpy arrays ``(m, NB_FIELDS)`` (the kernel compiled), else
        lists of lists."""
        self.reads_intents = config.algo in NEGOTIATING_ALGOS
        self.reach = reach(config.interaction_radius)
        self.wall_far = min(self.reach, VIEW_RADIUS)
        walls = config.walls().tolist()
        check_cell_order(walls)
        self.n_walls = len(walls)
        n, cells = config.n_agents, config.width * config.height
        wall_ids = np.full(cells, -1, dtype=np.int64)
        for k, (x, y) in enumerate(walls):
            wall_ids[y * config.width + x] = n + k
        self.wall_ids = wall_ids
        """The id of the wall on each cell (``y * width + x``), -1 for none: walls are bodies
        ``n_agents``, ``n_agents + 1``... in cell order."""
        self.wall_x = np.array([x for x, _ in walls], dtype=np.int64)
        self.wall_y = np.array([y for _, y in walls], dtype=np.int64)
        """The walls' cells, in cell order, as the known map reads them (``learning.known_map``)."""
        self.size = n + min(self.n_walls, (2 * self.wall_far + 1) ** 2)
        """The most rows an observation has: every other agent, and the walls in reach."""
        self.out = self._buffer(self.size, NB_FIELDS)
        """The kernel's rows, written afresh at each call."""
        self.answer, self.prev_x, self.prev_y, self.keep = (self._buffer(n) for _ in range(4))
        """The kernel's inputs by agent id (:meth:`load`), -1 for none; ``keep``: none kept."""
        self.wall_cells: object = wall_ids if self.arrays else wall_ids.tolist()
        """:attr:`wall_ids` as the kernel reads them."""

    def _buffer(self, size: int, width: int = 0):
        if self.arrays:
            return np.zeros((size, width) if width else size, dtype=np.int64)
        return [[0] * width for _ in range(size)] if width else [0] * size

    def __call__(self, obs: Observation, answers: dict[int, int], announcing: bool,
                 previous: dict[int, tuple[int, int]], was_at: tuple[int, int] | None,
                 cells=None, parked=None):
        """The visible neighbours within the learner's reach (``learning.fields.reach``: no other
        can change its decision or its learning) in id order, each with its announced move where
        it answered (``answers``), and its cell a tick ago where DAQL remembers it
        (``previous``); then the walls within reach, each known to stay where it is within the
        negotiation radius (as the simulator reads a scripted obstacle), unless nobody announces
        (``announcing``: not at an episode's end, nor once arrived), and seen a tick ago where
        the agent's cell then (``was_at``) saw it. ``cells`` and ``parked``: the observation's
        neighbours and parked ids as the kernel reads them, where the caller has them
        (``learning.planner.Plan``). Fresh rows: an array ``(m, NB_FIELDS)`` where the kernel is
        compiled (:attr:`arrays`), else lists. The agent's decision reads the same rows in its
        own kernel (``learning.decision.agent_decision``), over :meth:`load`'s buffers."""
        config, (x, y) = self.config, obs.position
        cells, parked, was_x, was_y = self.load(obs, answers, previous, was_at, cells, parked)
        m = self._rows(cells, len(cells), self.reach, self.reach, self.keep, parked, len(parked),
                       x, y, self.reach, self.answer, self.prev_x, self.prev_y, was_x, was_y,
                       announcing and self.reads_intents, self.wall_cells, self.n_walls,
                       self.wall_far, config.interaction_radius, config.meet_only, config.width,
                       config.height, self.out)
        out = self.out
        return out[:m].copy() if self.arrays else [list(row) for row in out[:m]]

    def load(self, obs: Observation, answers: dict[int, int],
             previous: dict[int, tuple[int, int]], was_at: tuple[int, int] | None,
             cells=None, parked=None) -> tuple:
        """Write ``answers`` and ``previous`` into the kernel's buffers (:attr:`answer`,
        :attr:`prev_x`, :attr:`prev_y`; -1 elsewhere); the neighbours and parked ids as the
        kernel reads them (``cells`` and ``parked`` where the caller has them), and the cell
        ``was_at`` as ``(was_x, was_y)`` (-1 for none)."""
        answer, prev_x, prev_y = self.answer, self.prev_x, self.prev_y
        if cells is None:
            cells, parked = unpack_seen(obs, self.arrays)
        if self.arrays:
            answer.fill(-1)
            prev_x.fill(-1)
            prev_y.fill(-1)
        else:
            answer[:] = prev_x[:] = prev_y[:] = [-1] * self.config.n_agents
        for j, action in answers.items():
            answer[j] = action
        for j, (px, py) in previous.items():
            prev_x[j], prev_y[j] = px, py
        was_x, was_y = (-1, -1) if was_at is None else was_at
        return cells, parked, was_x, was_y
