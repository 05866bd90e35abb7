"""Each agent an entity of its own in the world view, so that a person can pick one: select it,
hide it, follow it; at :data:`GROUPED_FROM` agents and more, groups of :data:`GROUP_SIZE` (an
agent is then an instance of its group's entities: clicking its disc selects it).

Agent ``i`` is ``world/agents/<i>`` (a group: ``world/agents/group-<k>``, agents ``64k`` to
``64k + 63``), and under it its parts: :data:`DISC` (where it stands), :data:`TRAIL` (its last
cells), :data:`PATH` (the step that brought it there: on the ``episode`` timeline, the whole
episode's path), :data:`INTENT` (the move it announced), :data:`WAITS` (whose intents it waited
for), :data:`GOAL` and :data:`START`. Hiding ``world/agents/3`` in the viewer hides all of that.

Cost: every part of every agent goes to Rerun in one call per flush (:class:`EntityColumns`, a
single Arrow record batch whose columns name their entities), not one call per entity: the
columns are built for all agents at once and sliced, without copying, per entity.
"""

import numpy as np
import pyarrow as pa
import rerun as rr

ROOT = "world/agents"

GROUPED_FROM = 16
"""From this many agents on, the world view's agents are groups, not one entity each, so that the
web viewer draws them on the grid. Rerun orders 2D layers by a depth offset, one step for each
(visualizer, entity) pair in the view, in order of draw order, whatever the draw orders' values;
under WebGL (its GLES tier) a step also scales what it draws about the view's centre, by about
3e-4 (``5120 * 2**-24``, Rerun's ``depth_offset.wgsl``). The grid, drawn first, and the agents'
discs, drawn over each agent's goal, start, path, route and trail, are then some 6 steps an
agent apart: at 64 agents of their own the grid was drawn about 0.88 the discs' size, and agents at
the border stood up to two cells off it (``tests/test_browser.py``). On a grid of ``w`` cells
an agent at the border is off by ``w / 2 * 3e-4 * 6`` cells an agent: 0.09 cells for 8 agents on
11 x 11, 0.25 for 16 on 16 x 16, 0.6 for 31 on 22 x 22. One entity an agent (one pair) would
still make 64 agents 64 steps apart, so the agents go in groups; a group is 8 pairs."""
GROUP_SIZE = 64
"""Agents per group from :data:`GROUPED_FROM` on: 16 to 64 agents make 1 group, 128 make 2.
(Groups of 16, 8 at 128 agents, made the web viewer draw the 40 x 40 grid smaller than the
world view's bounds: :data:`GROUPED_FROM` says why.)"""

DISC, TRAIL, PATH, INTENT, WAITS, GOAL, START = ("disc", "trail", "path", "intent", "waits",
                                                 "goal", "start")
ROUTE = "route"
"""From :data:`CROWDED_FROM` agents on: the agent's whole path of an episode, at the episode's
end, in bands faded by age (``recording.fading``); nothing from the next episode's start."""
PER_TICK = (DISC, TRAIL, PATH, INTENT, WAITS)
PER_EPISODE = (GOAL, START)
EPISODE_WIDE = (PATH, INTENT, WAITS)
"""The parts the world view shows for a whole episode at once on the ``episode`` timeline,
below :data:`CROWDED_FROM` agents."""
CROWDED_FROM = 32
"""From this many agents on, the world view's episode (the ``episode`` timeline) shows each
agent's path alone, faded by age (:data:`ROUTE`), not its every move and wait: 64 agents' 256
steps of arrows covered the grid. Where they waited, the jams' heat map shows; each move and
wait, the ``tick`` timeline."""
CROWDED_EPISODE_WIDE: tuple[str, ...] = ()
"""Nothing a tick: the route, at the episode's end, is what the episode view shows."""


def episode_parts(n_agents: int) -> tuple[str, ...]:
    """The parts the ``episode`` timeline shows of a whole episode at once."""
    return EPISODE_WIDE if n_agents < CROWDED_FROM else CROWDED_EPISODE_WIDE


def crowded(n_agents: int) -> bool:
    return n_agents >= CROWDED_FROM


def owners(n_agents: int) -> list[tuple[str, np.ndarray]]:
    """Each entity of the agents, ``(path, the agents it holds)``, in order of their agents."""
    if n_agents < GROUPED_FROM:
        return [(f"{ROOT}/{i}", np.array([i])) for i in range(n_agents)]
    return [(f"{ROOT}/group-{k}", np.arange(first, min(first + GROUP_SIZE, n_agents)))
            for k, first in enumerate(range(0, n_agents, GROUP_SIZE))]


def owner_index(n_agents: int) -> np.ndarray:
    """For each agent, the index of its entity in :func:`owners`."""
    return np.arange(n_agents) // (1 if n_agents < GROUPED_FROM else GROUP_SIZE)


def part_paths(n_agents: int, part: str) -> list[str]:
    """Every entity's ``part``, e.g. ``world/agents/3/intent``."""
    return [f"{path}/{part}" for path, _ in owners(n_agents)]


def agents_of(entity: str, n_agents: int) -> np.ndarray | None:
    """The agents an entity path under :data:`ROOT` holds (None: not an agents' entity)."""
    head = entity.lstrip("/")
    if not head.startswith(ROOT + "/"):
        return None
    name = head[len(ROOT) + 1:].split("/")[0]
    for path, agents in owners(n_agents):
        if path == f"{ROOT}/{name}":
            return agents
    return None


def by_entity(rows: np.ndarray, agents: np.ndarray, k: int, n_agents: int
              ) -> tuple[np.ndarray, np.ndarray]:
    """Items of ``k`` rows (an item: its row, its agent) in the order :class:`EntityColumns`
    sends them: ``(order, lengths)``, the items by entity, then row, then agent, and how many
    each entity's row holds (entity ``e``'s rows are ``lengths[e * k:(e + 1) * k]``)."""
    owner = owner_index(n_agents)[agents]
    order = np.lexsort((agents, rows, owner))
    lengths = np.bincount(owner * k + rows, minlength=len(owners(n_agents)) * k)
    return order, lengths


class EntityColumns:
    """The columns of many entities on one index, sent in one call (``send_record_batch``).

    :meth:`add` takes a component column partitioned into ``entities * k`` rows, entity by
    entity (see :func:`by_entity`); each entity's ``k`` rows become its own column."""

    def __init__(self, index: list, k: int) -> None:
        self.k = k
        self._fields: list[pa.Field] = []
        self._arrays: list[pa.Array] = []
        for column in index:
            name = column.timeline_name()
            self._fields.append(pa.field(name, pa.int64(), metadata={
                "rerun:kind": "index", "rerun:index_name": name}))
            self._arrays.append(column.as_arrow_array().cast(pa.int64()))

    def add(self, paths: list[str], columns) -> None:
        """``columns``: an archetype's partitioned component columns, ``len(paths) * k`` rows."""
        for column in columns:
            descriptor = column.component_descriptor()
            array = column.as_arrow_array()
            meta = {"rerun:kind": "data", "rerun:component": descriptor.component,
                    "rerun:component_type": descriptor.component_type or "",
                    "rerun:archetype": descriptor.archetype or ""}
            for e, path in enumerate(paths):
                entity = "/" + path
                self._fields.append(pa.field(f"{entity}:{descriptor.component}", array.type,
                                             metadata={**meta, "rerun:entity_path": entity}))
                self._arrays.append(array.slice(e * self.k, self.k))

    def send(self, stream: rr.RecordingStream) -> None:
        if len(self._arrays) > 2 and self.k:
            stream.send_record_batch(pa.RecordBatch.from_arrays(
                self._arrays, schema=pa.schema(self._fields)), index=["tick", "episode"])
