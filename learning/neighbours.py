"""The neighbours as a learner reads them at an observation: whose intents it waits for
(:func:`awaited`), whose it knows without waiting (:func:`staying`), and their rows
(:class:`NeighbourRows`, ``learning.fields.NB_*``). The agent decides with them; the world reads
the same when it checks the agent's learning record (``world.records``). Each row is written by
one kernel, :func:`neighbour_row`, which the simulator's ``sim.episode.neighbour_rows`` calls
too."""

import numpy as np

from nnql_swarm.learning.fields import (
    NB_FIELDS, NB_ID, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_PARKED, NB_PREV_X, NB_PREV_Y,
    NB_STATE_X, NB_STATE_Y, NB_X, NB_Y, reach,
)
from nnql_swarm.learning.known_map import check_cell_order
from nnql_swarm.learning.plan import awaited_into, staying_into
from nnql_swarm.protocol.actions import STAY, VIEW_RADIUS, sees, target_x, target_y, within
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.jit import COMPILED, inline_kernel, ints, python_values


@inline_kernel
def neighbour_row(row, j, jx, jy, known, action, parked, px, py, width, height):
    """Write body ``j``'s neighbour row (``learning.fields.NB_*``, but ``NB_ROW``): its cell
    ``(jx, jy)``; whether its move this tick is ``known`` and the cell it goes to (by
    ``action``, where known; else its cell), which is also the cell its state reads (the
    simulator's lookahead overwrites that with the cell planned further on); whether it is
    ``parked`` on its goal; and its cell a tick ago ``(px, py)``, ``(-1, -1)`` where the agent's
    cell then did not see it."""
    row[NB_ID] = j
    row[NB_X] = jx
    row[NB_Y] = jy
    if known:
        nx = target_x(jx, action, width)
        ny = target_y(jy, action, height)
    else:
        nx = jx
        ny = jy
    row[NB_KNOWN] = 1 if known else 0
    row[NB_NEXT_X] = nx
    row[NB_NEXT_Y] = ny
    row[NB_STATE_X] = nx
    row[NB_STATE_Y] = ny
    row[NB_PARKED] = 1 if parked else 0
    row[NB_PREV_X] = px
    row[NB_PREV_Y] = py


write_row = getattr(neighbour_row, "py_func", neighbour_row)
""":func:`neighbour_row` as plain Python, on a list row (the agent's rows are lists, whether or
not the kernel is compiled in this process)."""
from nnql_swarm.protocol.messages import Observation
from nnql_swarm.protocol.ranks import in_reach


def awaited(obs: Observation, config: SwarmConfig) -> list[int]:
    """The neighbours whose intents the observing agent waits for at this tick (none for QL, and
    none at an episode's end, where everybody stays)."""
    return [j for j, _, _ in awaited_cells(obs, config)]


def awaited_cells(obs: Observation, config: SwarmConfig) -> list[tuple[int, int, int]]:
    """:func:`awaited` as ``(id, x, y)`` (``learning.plan.awaited_into``)."""
    if config.algo not in NEGOTIATING_ALGOS or obs.episode_end:
        return []
    neighbours, (x, y) = obs.neighbours, obs.position
    out = ints([0] * len(neighbours))
    count = awaited_into(_rows(neighbours), len(neighbours), ints(obs.parked), len(obs.parked),
                         x, y, obs.rank, obs.tick, config.n_agents, config.interaction_radius,
                         config.meet_only, obs.arrived and not config.step_aside, out)
    return [neighbours[i] for i in python_values(out)[:count]]


def staying(obs: Observation, config: SwarmConfig) -> list[int]:
    """Under the ``meet`` rule, the parked neighbours whose intents the observing agent knows
    without waiting: those ``protocol.ranks.waits_for`` names among the parked ones of the
    observation, each of which stays on its goal (its intent is STAY;
    ``learning.plan.staying_into``)."""
    if (not (config.meet_only and obs.parked) or config.algo not in NEGOTIATING_ALGOS
            or obs.episode_end):
        return []
    neighbours, (x, y) = obs.neighbours, obs.position
    out = ints([0] * len(neighbours))
    count = staying_into(_rows(neighbours), len(neighbours), ints(obs.parked), len(obs.parked),
                         x, y, obs.rank, obs.tick, config.n_agents, config.interaction_radius,
                         out)
    return [neighbours[i][0] for i in python_values(out)[:count]]


def _rows(neighbours):
    """An observation's neighbours as the kernel reads them: an array ``(k, 3)`` where it is
    compiled, else the tuples themselves."""
    return np.array(neighbours, dtype=np.int64).reshape(len(neighbours), 3) if COMPILED \
        else neighbours


class NeighbourRows:
    """The learner's neighbour rows (``learning.fields.NB_*``) for an observation: what an agent
    reads its neighbours as, and what the world reads them as when it checks the agent's learning
    record (``world.records``)."""

    def __init__(self, config: SwarmConfig) -> None:
        self.config = config
        self.reads_intents = config.algo in NEGOTIATING_ALGOS
        self.reach = reach(config.interaction_radius)
        walls = config.walls().tolist()
        check_cell_order(walls)
        self._walls = {y * config.width + x: config.n_agents + k
                       for k, (x, y) in enumerate(walls)}
        self._walls_near: dict[tuple[int, int], list[tuple[int, int, int]]] = {}
        self.wall_x, self.wall_y = ints([x for x, _ in walls]), ints([y for _, y in walls])
        """The walls' cells, in cell order, as the known map reads them (``learning.known_map``)."""

    def __call__(self, obs: Observation, answers: dict[int, int], announcing: bool,
                 previous: dict[int, tuple[int, int]],
                 was_at: tuple[int, int] | None) -> list[list[int]]:
        """The visible neighbours within the learner's reach (``learning.fields.reach``: no other
        can change its decision or its learning) in id order, each with its announced move where
        it answered (``answers``), and its cell a tick ago where DAQL remembers it
        (``previous``); then the walls within reach, each known to stay where it is within the
        negotiation radius (as the simulator reads a scripted obstacle), unless nobody announces
        (``announcing``: not at an episode's end, nor once arrived), and seen a tick ago where
        the agent's cell then (``was_at``) saw it."""
        w, h = self.config.width, self.config.height
        parked = set(obs.parked)
        (x, y), far = obs.position, self.reach
        rows = []
        for j, jx, jy in within(obs.neighbours, x, y, far):
            action = answers.get(j)
            px, py = previous.get(j, (-1, -1))
            row = [0] * NB_FIELDS
            write_row(row, j, jx, jy, action is not None, STAY if action is None else action,
                      j in parked, px, py, w, h)
            rows.append(row)
        if self._walls:
            knows = announcing and self.reads_intents
            radius, meet = self.config.interaction_radius, self.config.meet_only
            for j, jx, jy in self._walls_within(x, y):
                px, py = (jx, jy) if was_at is not None and sees(*was_at, jx, jy) else (-1, -1)
                row = [0] * NB_FIELDS
                write_row(row, j, jx, jy, knows and in_reach(x, y, jx, jy, radius, meet), STAY,
                          False, px, py, w, h)
                rows.append(row)
        return rows

    def _walls_within(self, x: int, y: int) -> list[tuple[int, int, int]]:
        """The walls within reach and view of cell ``(x, y)`` as ``(id, x, y)`` in id order
        (cell order), once per cell."""
        near = self._walls_near.get((x, y))
        if near is None:
            w, h, far = self.config.width, self.config.height, min(self.reach, VIEW_RADIUS)
            near = [(self._walls[cy * w + cx], cx, cy)
                    for cy in range(max(0, y - far), min(h, y + far + 1))
                    for cx in range(max(0, x - far), min(w, x + far + 1))
                    if cy * w + cx in self._walls]
            self._walls_near[(x, y)] = near
        return near
