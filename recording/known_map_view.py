"""One agent's known map and planned path in the recording, tick by tick, as its learner sees them.

A learner whose destination seeking reads the map (``--ds-state waypoint|progress`` or
``--ds-reward path|flat``, the default preset) knows only the walls it has seen and plans on
them, the unknown taken as free (``learning.known_map``). The recording shows that for one agent
(``--map-agent``, default 0) under ``known_map/``: the walls it knows (dark blocks), the walls
it has not seen yet (pale outlines), the parked agents it plans around (``--detour``: grey
discs), its cell, its goal, and its planned path on that map (a line in its colour from its cell
to its goal; none where the known map cuts it off).

Nothing is reported by the agent: :class:`KnownMapViz` replays the agent's observations, as the
world makes them at each tick (its cell, its goal, the others in view and which of them are
parked), through the learner's own kernel (``learning.learner.observe_map`` on a buffer of its
own, with the neighbour rows of ``learning.rows.NeighbourRows``), and follows the path with
``learning.known_map.waypoint_move``, the move the waypoint state reads. A run resumed from a
checkpoint starts this replay afresh: its known walls are those seen since the resume.
"""

import numpy as np
import rerun as rr

from nnql_swarm.learning.rows import NeighbourRows
from nnql_swarm.learning.known_map import (
    MAP_HEADER, MAP_KNOWN, MAP_PARKED, SECTIONS, fresh_map, map_size, path_length, waypoint_move,
)
from nnql_swarm.learning.fields import NB_FIELDS, Grid, Sight, learner_params
from nnql_swarm.learning.learner import observe_map
from nnql_swarm.learning.readings import uses_map
from nnql_swarm.protocol.actions import VIEW_RADIUS, target_x, target_y, within
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import ints, rows
from nnql_swarm.protocol.messages import WORLD_SENDER, Observation, pack_ids, pack_neighbours
from nnql_swarm.recording.columns import time_columns
from nnql_swarm.recording.palette import WALL_COLOUR
from nnql_swarm.recording.world import WALL_HALF, WALL_LINE

ROOT = "known_map"
GRID, KNOWN, UNSEEN, PARKED = (f"{ROOT}/grid", f"{ROOT}/walls/known", f"{ROOT}/walls/unseen",
                               f"{ROOT}/parked")
AGENT, GOAL, PATH = f"{ROOT}/agent", f"{ROOT}/goal", f"{ROOT}/path"

UNSEEN_COLOUR = (175, 180, 195)
"""A wall the agent has not seen yet: a pale outline, apart from the known walls' dark blocks."""
PARKED_COLOUR = (140, 140, 140)


def shows_known_map(config: SwarmConfig) -> bool:
    """Whether the run's learners read a known map (else there is none to show)."""
    return bool(uses_map(ints(learner_params(config)[0])))


class KnownMapViz:
    """Replays agent ``agent``'s observations into its known map; buffers each tick's picture
    and sends it in columns when the world's logger flushes (:meth:`flush`)."""

    def __init__(self, config: SwarmConfig, agent: int, stream: rr.RecordingStream,
                 colour: np.ndarray) -> None:
        self.config, self.agent, self.rec = config, agent, stream
        self.params = ints(learner_params(config)[0])
        self.wmap = ints([0] * map_size(config.width, config.height))
        fresh_map(self.wmap)
        self.rows = NeighbourRows(config)
        self.walls = config.walls()
        self._known = -1  # the known walls' count last sent
        self._ticks: list[tuple] = []  # tick, episode, cell, goal, path, parked, known or None
        self._log_static(colour)

    def _log_static(self, colour: np.ndarray) -> None:
        c, rec = self.config, self.rec
        xs, ys = np.arange(c.width + 1) - 0.5, np.arange(c.height + 1) - 0.5
        lines = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
        rec.log(GRID, rr.LineStrips2D(lines, colors=[[200, 200, 200]], radii=-0.5,
                                      draw_order=2.0), static=True)
        rec.log(KNOWN, rr.Boxes2D.from_fields(colors=[WALL_COLOUR], radii=WALL_LINE,
                                              draw_order=5.0), static=True)
        rec.log(UNSEEN, rr.Boxes2D.from_fields(colors=[UNSEEN_COLOUR], radii=0.05,
                                               draw_order=4.0), static=True)
        rec.log(PARKED, rr.Points2D.from_fields(colors=[PARKED_COLOUR], radii=0.35,
                                                draw_order=6.0), static=True)
        rec.log(PATH, rr.LineStrips2D.from_fields(colors=[colour], radii=0.12, draw_order=10.0),
                static=True)
        rec.log(GOAL, rr.Boxes2D.from_fields(colors=[colour], radii=0.08, show_labels=True,
                                             labels=[f"goal {self.agent}"], draw_order=8.0),
                static=True)
        rec.log(AGENT, rr.Points2D.from_fields(colors=[colour], radii=0.4,
                                               labels=[f"agent {self.agent}"], show_labels=True,
                                               draw_order=20.0), static=True)

    def observe(self, tick: int, episode: int, starts: bool, cells, arrived, goal) -> None:
        """The agent's observation at ``tick``: every agent's ``cells`` and ``arrived`` flags as
        the tick started, its ``goal``; ``starts``: the episode's first tick."""
        c, i = self.config, self.agent
        (x, y), (gx, gy) = cells[i], goal
        others = [(j, jx, jy) for j, (jx, jy) in enumerate(cells) if j != i]
        neighbours = within(others, x, y, VIEW_RADIUS)
        parked = [j for j, _, _ in neighbours if arrived[j]]
        obs = Observation(c.run_id, tick, WORLD_SENDER, i, episode, 0, (x, y), (gx, gy),
                          pack_neighbours(neighbours), 0, 0.0, 0.0, False, bool(arrived[i]),
                          False, pack_ids(parked))
        near = self.rows(obs, {}, False, {}, None)
        grid = Grid(c.width, c.height, self.rows.wall_x, self.rows.wall_y, 0,
                    len(self.rows.wall_x))
        sight = Sight(x, y, gx, gy, rows(near, NB_FIELDS), len(near), starts)
        observe_map(self.params, self.wmap, grid, sight)
        known = int(self.wmap[MAP_KNOWN])
        walls = None
        if known != self._known:
            self._known = known
            cells_known = np.asarray(self.wmap[MAP_HEADER:MAP_HEADER + c.width * c.height]) != 0
            seen = cells_known[self.walls[:, 1] * c.width + self.walls[:, 0]] if len(self.walls) \
                else np.zeros(0, dtype=bool)
            walls = (self.walls[seen], self.walls[~seen])
        self._ticks.append((tick, episode, (x, y), (gx, gy), self.path(x, y, gx, gy),
                            self.parked_cells(), walls))

    def path(self, x: int, y: int, gx: int, gy: int) -> list[tuple[int, int]]:
        """The planned path from ``(x, y)`` to the goal on the known map, as the learner's
        waypoint follows it; just the cell where the map cuts it off from its goal."""
        c = self.config
        cells = [(x, y)]
        for _ in range(max(path_length(self.wmap, x, y, c.width, c.height), 0)):
            move = waypoint_move(self.wmap, x, y, gx, gy, c.width, c.height)
            x, y = target_x(x, move, c.width), target_y(y, move, c.height)
            cells.append((x, y))
        return cells

    def parked_cells(self) -> list[tuple[int, int]]:
        """The parked agents' cells the field plans around (``learning.known_map.see_parked``)."""
        c = self.config
        listed = MAP_HEADER + (SECTIONS - 1) * c.width * c.height
        return [divmod(int(self.wmap[listed + k]), c.width)[::-1]
                for k in range(int(self.wmap[MAP_PARKED]))]

    def flush(self) -> None:
        """Send the buffered ticks, one call per entity."""
        if not self._ticks:
            return
        ticks, episodes, here, goals, paths, parked, walls = zip(*self._ticks)
        self._ticks = []
        index = time_columns(ticks, episodes)
        rec = self.rec
        rec.send_columns(AGENT, index, rr.Points2D.columns(
            positions=np.array(here, dtype=np.float32)))
        rec.send_columns(GOAL, index, rr.Boxes2D.columns(
            centers=np.array(goals, dtype=np.float32),
            half_sizes=np.full((len(goals), 2), 0.42, np.float32)))
        rec.send_columns(PATH, index, rr.LineStrips2D.columns(
            strips=[np.array(p, dtype=np.float32) for p in paths]))
        rec.send_columns(PARKED, index, rr.Points2D.columns(
            positions=np.array([cell for cells in parked for cell in cells],
                               dtype=np.float32).reshape(-1, 2)
        ).partition([len(cells) for cells in parked]))
        changed = [k for k, w in enumerate(walls) if w is not None]
        if changed:
            at = time_columns([ticks[k] for k in changed], [episodes[k] for k in changed])
            for path, part in ((KNOWN, 0), (UNSEEN, 1)):
                boxes = [walls[k][part] for k in changed]
                rec.send_columns(path, at, rr.Boxes2D.columns(
                    centers=np.concatenate(boxes).astype(np.float32).reshape(-1, 2),
                    half_sizes=np.full((sum(map(len, boxes)), 2),
                                       WALL_HALF if part == 0 else 0.4, np.float32),
                ).partition([len(b) for b in boxes]))
