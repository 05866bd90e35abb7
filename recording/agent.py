"""What one agent learned, in Rerun: its Q-tables as 21 x 21 heat maps, and its negotiation timing.

Every tenth episode and the last (from the ``on_episode_end`` hook of ``agent.agent_node.run_agent`` and
``sim.inprocess.run_in_process``) each agent logs, under ``agents/<id>/``:

- ``q_ds/value``: an RGB image, one pixel per egocentric offset ``(dx, dy)`` of the *goal* from
  the agent (the agent sits at the centre pixel, marked by ``q_ds/self``; ``q_ds/frame`` outlines
  the window); its colour is ``log(1 + max_a Q_DS[s, a])`` on a fixed scale from 0 to the most
  the table can learn (:func:`learnable_bound`; viridis, dark low, bright high); light grey where
  the value is still above that bound (an optimistic start not yet explored away), white
  where no entry of the state moved off its initial value (Q values are never negative here, as
  no reward is);
- ``q_ds/note``: a line in the picture when no entry of the table has moved off its initial
  value (e.g. Q_CA of a run without collisions), so that the view says why it is blank;
- ``q_ds/policy``: an arrow per pixel for ``argmax_a Q_DS[s, a]``, ``q_ds/stay`` a dot where STAY
  is best (nothing where every action ties, e.g. never visited);
- ``q_ca/value``, ``q_ca/policy``, ``q_ca/stay``, ``q_ca/self``, ``q_ca/frame``, ``q_ca/note``:
  the same for ``Q_CA``, whose state is a *neighbour's* offset (nnQL: its announced next cell,
  QL: its current cell).

Where destination seeking reads the agent's known map instead of the goal's offset
(``--ds-state waypoint`` or ``progress``, the default preset's), its few states have no place on
the offset window: ``q_ds/table`` is then a markdown table (:func:`ds_table`), one row per state
saying what the state is (the next cell of the planned path; or the moves that bring the agent
nearer on its map), whether it was met yet, the best move and its value, and whether that move
follows the planned path.

Agent 0 also logs, every episode, the share of its tables' states met so far
(``metrics/explored/q_ds``, ``.../q_ca``: :func:`states_met`), the exploration curve. Q_CA is left
out where it cannot learn (``recording.shown``).

Only the first ``recording.loggers.RECORDED_AGENTS`` agents log these, and only agent 0 where
the agents share one table (every copy is the same table). What an agent logs is
buffered and sent in columns every few seconds (:class:`AgentViz`).

Pixel ``(column, row) = (dx + 10, dy + 10)``; rows grow downwards, like the world's ``y``, so an
arrow points the way the agent would move on the grid. The colour scale is fixed for the run,
so colours compare across episodes and agents.

Negotiation timing (distributed agents only, :class:`TimedBrain`): the wall time from the agent's
first intent query of a tick to its last answer or time-out, i.e. how long it waited for its
higher-ranked neighbours, averaged per episode over the ticks where it asked anyone
(``metrics/negotiation/latency_ms/<id>``), and the queries left unanswered
(``metrics/negotiation/unanswered/<id>``). The in-process runner has no such wait to measure.
"""

import time
from typing import Callable

import numpy as np
import rerun as rr

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.actions import (
    ACTION_NAMES, MOVES, N_ACTIONS, N_STATES, STAY, VIEW_RADIUS, WINDOW, offset_state,
)
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.messages import Observation
from nnql_swarm.recording.columns import FlushClock, SeriesColumns, time_columns
from nnql_swarm.recording.shown import ca_learns
from nnql_swarm.recording.sinks import close_stream

TABLES = ("q_ds", "q_ca")

HEATMAP_EVERY = 10

FLUSH_EPISODES = 200
"""The most episodes buffered before the agent's logging is sent (or after ``FLUSH_SECONDS``)."""


def logs_heat_maps(episode: int, episodes: int) -> bool:
    """Whether an agent logs its heat maps at the end of ``episode``: every tenth and the last."""
    return episode % HEATMAP_EVERY == 0 or episode == episodes - 1
"""Heat maps are logged every this many episodes (and at the run's last): late in a run there are
tens of episodes a second, and every picture is data the recording keeps."""

_VIRIDIS = np.array([
    (68, 1, 84), (72, 40, 120), (62, 74, 137), (49, 104, 142), (38, 130, 142),
    (31, 158, 137), (53, 183, 121), (109, 205, 89), (180, 222, 44), (253, 231, 37),
], dtype=np.float64)
UNVISITED = (255, 255, 255)
"""States none of whose entries moved off the initial value: white, the view's background
(the viewer draws an image's transparent pixels black)."""
OPTIMISTIC = (205, 205, 205)
"""States whose best value is still above anything the table can learn: light grey."""
FRAME = (120, 120, 120)
NOTHING_LEARNED = "nothing learned yet: every entry is still at its initial value"
DS_STATE_TITLES = {
    "goal": "by the goal's offset from the agent",
    "waypoint": "by the next cell of its planned path on the map it knows",
    "progress": "by the moves that bring it nearer its goal on the map it knows",
}
"""What destination seeking's state is, per ``--ds-state``: the heat maps' titles say it."""


def agent_path(agent: int) -> str:
    return f"agents/{agent}"


def explored_path(table: str) -> str:
    return f"metrics/explored/{table}"


EXPLORED_COLOURS = {"q_ds": (60, 120, 200), "q_ca": (200, 110, 40)}


def states_met(q: np.ndarray, initial: float, ds_state: str = "goal") -> float:
    """The share of a table's states met so far: some entry moved off its ``initial`` value. A
    map-reading Q_DS (``ds_state`` waypoint or progress) counts its few states
    (:func:`ds_states`); a table of several blocks of 441 offsets counts an offset met in any."""
    if ds_state != "goal":
        rows = [state for state, _, _ in ds_states(ds_state)]
        return float(np.any(np.asarray(q)[rows] != initial, axis=-1).mean())
    blocks = np.asarray(q).reshape(-1, N_STATES, N_ACTIONS)
    return float(np.any(blocks != initial, axis=(0, 2)).mean())


def latency_path(agent: int) -> str:
    return f"metrics/negotiation/latency_ms/{agent}"


def unanswered_path(agent: int) -> str:
    return f"metrics/negotiation/unanswered/{agent}"


def viridis(t: np.ndarray) -> np.ndarray:
    """Map values in [0, 1] to viridis RGB bytes."""
    x = np.clip(t, 0.0, 1.0) * (len(_VIRIDIS) - 1)
    low = np.floor(x).astype(int)
    high = np.minimum(low + 1, len(_VIRIDIS) - 1)
    frac = (x - low)[..., None]
    return (_VIRIDIS[low] * (1 - frac) + _VIRIDIS[high] * frac).astype(np.uint8)


def learnable_bound(table: str, config: SwarmConfig) -> float:
    """The largest value a table can learn: Q_DS the goal reward (a step's own reward is at most
    1, so ``1 / (1 - gamma)`` bounds a path that never arrives), Q_CA the no-collision reward 10
    every step, discounted: ``10 / (1 - gamma)``."""
    if table == "q_ds":
        return max(config.goal_reward, 1.0 / (1.0 - config.gamma))
    return 10.0 / (1.0 - config.gamma)


def table_picture(q: np.ndarray, initial: float = 0.0, bound: float | None = None) -> dict:
    """One Q-table as a heat map and a policy over the 21 x 21 offset window.

    A table of several blocks of 441 states (a neighbour's state with its known move, or its
    intent known or not) shows, per offset, the block with the best value. Returns ``value``
    (max over actions, ``[row, column] = [dy + 10, dx + 10]``), ``best`` (argmax), ``visited``
    (some action's value moved off ``initial``), ``decided`` (not every action tied) and
    ``image`` (RGB bytes): ``log(1 + value)`` from 0 to ``log(1 + bound)`` in viridis, values
    above ``bound`` :data:`OPTIMISTIC`, states not visited :data:`UNVISITED` (white).
    Without ``bound``, the scale ends at the largest value visited.
    """
    blocks = np.asarray(q).reshape(-1, N_STATES, N_ACTIONS)
    best_block = blocks.max(axis=-1).argmax(axis=0)
    table = blocks[best_block, np.arange(N_STATES)]
    grid = table.reshape(WINDOW, WINDOW, N_ACTIONS).transpose(1, 0, 2)
    value = grid.max(axis=-1)
    best = grid.argmax(axis=-1)
    visited = np.any(grid != initial, axis=-1)
    decided = value > grid.min(axis=-1)
    image = np.empty((WINDOW, WINDOW, 3), dtype=np.uint8)
    image[:] = UNVISITED
    if visited.any():
        # log scale: Q_DS spans 0.1 far from the goal to 10 next to it, Q_CA 0 to 25
        top = value[visited].max() if bound is None else bound
        shade = np.log1p(np.maximum(value, 0.0)) / max(np.log1p(max(top, 0.0)), 1e-12)
        image[visited] = viridis(shade[visited])
        image[visited & (value > top * (1 + 1e-9))] = OPTIMISTIC
    return {"value": value, "best": best, "visited": visited, "decided": decided, "image": image}


def ds_states(ds_state: str) -> list[tuple[int, str, int]]:
    """The destination-seeking states of a map-reading learner (``learning.learner.ds_state``), each
    as ``(state, what it is, moves that follow the planned path as bits)``; empty for the goal's
    offset, which the 21 x 21 picture shows."""
    moves = [name.lower() for name in ACTION_NAMES[:STAY]]
    if ds_state == "waypoint":
        return [(offset_state(int(dx), int(dy)), name, 1 << a)
                for a, (name, (dx, dy)) in enumerate(zip(moves, MOVES[:STAY]))] + \
            [(offset_state(0, 0), "none: on the goal, or cut off", 1 << STAY)]
    if ds_state == "progress":
        return [(mask, " or ".join(m for a, m in enumerate(moves) if mask >> a & 1)
                 if mask else "none: on the goal, or cut off", mask or 1 << STAY)
                for mask in range(1 << STAY)]
    return []


DS_STATE_HEADS = {"waypoint": "the next cell of the path", "progress": "moves that bring it nearer"}
"""The state column's heading in :func:`ds_table`."""


def ds_table(q_ds: np.ndarray, ds_state: str, initial: float, bound: float) -> tuple[str, bool]:
    """Q_DS of a map-reading learner as a markdown table, one row per state (:func:`ds_states`):
    what the state is, the best move and its value (or that the state was never met, or that
    every move ties), and whether that move follows the planned path; a value still above
    ``bound`` (what the table can learn: an optimistic start not explored yet) is starred.
    Returns the table and whether any entry moved off ``initial``."""
    lines = [f"| {DS_STATE_HEADS[ds_state]} | best move (value) | on the path |",
             "| --- | --- | --- |"]
    learned = optimistic = False
    for state, meaning, path_moves in ds_states(ds_state):
        values = np.asarray(q_ds[state], dtype=float)
        if np.all(values == initial):
            lines.append(f"| {meaning} | not met yet | |")
            continue
        learned = True
        best = int(values.argmax())
        star = "*" if values[best] > bound else ""
        optimistic |= bool(star)
        if np.all(values == values[best]):
            lines.append(f"| {meaning} | all tie ({values[best]:.2f}{star}) | |")
            continue
        follows = "yes" if path_moves >> best & 1 else "no"
        lines.append(f"| {meaning} | {ACTION_NAMES[best].lower()} ({values[best]:.2f}{star}) "
                     f"| {follows} |")
    if optimistic:
        lines.append(f"\n\\* above {bound:g}, all it can learn: its optimistic start "
                     f"({initial:g}), not explored yet")
    return "\n".join(lines), learned


def policy_marks(picture: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Arrow origins, vectors and colours for the decided non-STAY cells; STAY cell centres."""
    rows, cols = np.nonzero(picture["decided"])
    actions = picture["best"][rows, cols]
    centres = np.stack([cols + 0.5, rows + 0.5], axis=-1).astype(np.float32)
    moving = actions != STAY
    vectors = (MOVES[actions[moving]] * 0.42).astype(np.float32)
    origins = centres[moving] - vectors / 2
    shade = picture["image"][rows, cols].astype(float) @ np.array([0.299, 0.587, 0.114])
    colors = np.where((shade[moving] > 140)[:, None], [[20, 20, 20]], [[245, 245, 245]])
    return origins, vectors, colors.astype(np.uint8), centres[~moving]


class TimedBrain(AgentBrain):
    """An AgentBrain that times its negotiation: from choosing whose intents to wait for to
    deciding.

    ``agent.agent_node`` calls :meth:`neighbours_to_ask`, learns those intents (its queries, and what
    the answers relay), then calls :meth:`act` with them: the time between the two calls is the
    negotiation wait. Decisions are exactly those of AgentBrain.
    """

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        super().__init__(agent, config)
        self.last_tick = 0
        self.latencies_s: list[float] = []
        self.unanswered = 0
        self._asked: set[int] = set()
        self._asked_at = 0.0

    def neighbours_to_ask(self, obs: Observation, awaited: list[int]) -> list[int]:
        asked = super().neighbours_to_ask(obs, awaited)
        self._asked = set(asked)
        self._asked_at = time.perf_counter()
        return asked

    def act(self, obs: Observation, answers: dict[int, int], seen: tuple = (None, None)) -> int:
        if self._asked:  # answers may hold more: the arrived neighbours known to stay
            self.latencies_s.append(time.perf_counter() - self._asked_at)
            self.unanswered += len(self._asked - answers.keys())
            self._asked = set()
        self.last_tick = obs.tick
        return super().act(obs, answers, seen)

    def take_timings(self) -> tuple[list[float], int]:
        """The episode's latencies and unanswered count, reset for the next episode."""
        timings = (self.latencies_s, self.unanswered)
        self.latencies_s, self.unanswered = [], 0
        return timings


class AgentViz:
    """Logs one agent's Q-tables (and negotiation timing) at the end of every episode.

    Everything is buffered and sent in columns, a few calls per flush (``recording.columns``):
    after :data:`FLUSH_EPISODES` episodes or ``FLUSH_SECONDS`` of wall time, and at :meth:`close`.
    """

    def __init__(self, agent: int, config: SwarmConfig, stream: rr.RecordingStream,
                 tick_of_episode_end: Callable[[], int] | None = None,
                 heat_maps: bool = True) -> None:
        """``heat_maps``: whether this agent logs its tables (not where it shares agent 0's)."""
        self.agent = agent
        self.heat_maps = heat_maps
        self.config = config
        self.rec = stream
        self.tick_of_episode_end = tick_of_episode_end
        self.clock = FlushClock(FLUSH_EPISODES)
        self._episodes = 0  # buffered
        self._series = SeriesColumns()
        self._pictures: list[tuple[int, int, list[tuple]]] = []  # tick, episode, per table
        self._ds_tables: list[str] = []  # per entry of _pictures, where Q_DS is a table
        self.pictured = tuple(table for table in TABLES
                              if (table != "q_ds" or config.ds_state == "goal")
                              and (table != "q_ca" or ca_learns(config))) if heat_maps else ()
        """The tables drawn as 21 x 21 pictures; Q_DS of a map-reading learner is a table, and
        Q_CA is left out where it learns nothing (``recording.shown``)."""
        self.explored = tuple(table for table in TABLES if table != "q_ca" or ca_learns(config)) \
            if heat_maps and agent == 0 else ()
        """The tables whose share of states met this agent logs every episode: agent 0's."""
        for table in self.explored:
            stream.log(explored_path(table), rr.SeriesLines(
                names=table.upper(), colors=[EXPLORED_COLOURS[table]], widths=2.0), static=True)
        root = agent_path(agent)
        centre = np.array([[VIEW_RADIUS + 0.5, VIEW_RADIUS + 0.5]], dtype=np.float32)
        for table in self.pictured:
            stream.log(f"{root}/{table}/frame", rr.Boxes2D(
                centers=[[WINDOW / 2, WINDOW / 2]], sizes=[[WINDOW, WINDOW]], colors=[FRAME],
                radii=0.05, draw_order=45.0), static=True)
            stream.log(f"{root}/{table}/note", rr.Points2D.from_fields(
                radii=0.01, colors=[[40, 40, 40]], show_labels=True, draw_order=60.0), static=True)
            stream.log(f"{root}/{table}/self", rr.Boxes2D(
                centers=centre, sizes=[[1.0, 1.0]], colors=[[255, 60, 60]], radii=0.06,
                draw_order=50.0), static=True)
            stream.log(f"{root}/{table}/policy",
                       rr.Arrows2D.from_fields(radii=0.045, draw_order=40.0), static=True)
            stream.log(f"{root}/{table}/stay", rr.Points2D.from_fields(
                radii=0.11, colors=[[235, 235, 235]], draw_order=40.0), static=True)
        stream.log(latency_path(agent), rr.SeriesLines(names=f"agent {agent}"), static=True)
        stream.log(unanswered_path(agent), rr.SeriesLines(names=f"agent {agent}"), static=True)

    def on_episode_end(self, brain: AgentBrain, episode: int) -> None:
        """The ``on_episode_end(brain, episode)`` hook of the agent process and in-process run."""
        if isinstance(brain, TimedBrain):
            tick = brain.last_tick
        elif self.tick_of_episode_end is not None:
            tick = self.tick_of_episode_end()
        else:
            tick = 0
        if self.heat_maps and logs_heat_maps(episode, self.config.episodes):
            c, tables = self.config, dict(zip(TABLES, brain.learner.tables()))
            self._pictures.append((tick, episode, [
                (picture["image"], *policy_marks(picture), bool(picture["visited"].any()))
                for picture in (table_picture(tables[table], c.optimistic,
                                              learnable_bound(table, c))
                                for table in self.pictured)]))
            if "q_ds" not in self.pictured:
                text, _ = ds_table(tables["q_ds"], c.ds_state, c.optimistic,
                                   learnable_bound("q_ds", c))
                self._ds_tables.append(f"**Q_DS {DS_STATE_TITLES[c.ds_state]}**, at "
                                       f"episode {episode}\n\n{text}")
        if self.explored:
            c, tables = self.config, dict(zip(TABLES, brain.learner.tables()))
            for table in self.explored:
                self._series.add(explored_path(table), tick, episode, states_met(
                    tables[table], c.optimistic, c.ds_state if table == "q_ds" else "goal"))
        if isinstance(brain, TimedBrain):
            latencies, unanswered = brain.take_timings()
            if latencies:
                self._series.add(latency_path(self.agent), tick, episode,
                                 1000.0 * float(np.mean(latencies)))
            self._series.add(unanswered_path(self.agent), tick, episode, float(unanswered))
        self._episodes += 1
        if self.clock.due(self._episodes):
            self.flush()

    def flush(self) -> None:
        """Send the buffered heat maps and timings, one call per entity."""
        self.clock.flushed()
        self._episodes = 0
        self._series.send(self.rec)
        if not self._pictures:
            return
        ticks, episodes, tables = zip(*self._pictures)
        self._pictures = []
        index = time_columns(ticks, episodes)
        if self._ds_tables:
            self.rec.send_columns(f"{agent_path(self.agent)}/q_ds/table", index,
                                  rr.TextDocument.columns(
                                      text=self._ds_tables,
                                      media_type=[rr.MediaType.MARKDOWN] * len(self._ds_tables)))
            self._ds_tables = []
        image_format = rr.components.ImageFormat(width=WINDOW, height=WINDOW, color_model="RGB",
                                                 channel_datatype="U8")
        root = agent_path(self.agent)
        note_at = np.array([[WINDOW / 2, WINDOW / 4]], dtype=np.float32)
        for table, marks in zip(self.pictured, zip(*tables)):
            images, origins, vectors, colors, stays, learned = zip(*marks)
            self.rec.send_columns(f"{root}/{table}/note", index, rr.Points2D.columns(
                positions=np.concatenate([note_at[:0] if done else note_at for done in learned]),
                labels=[NOTHING_LEARNED for done in learned if not done],
            ).partition([0 if done else 1 for done in learned]))
            self.rec.send_columns(f"{root}/{table}/value", index, rr.Image.columns(
                buffer=[image.tobytes() for image in images], format=[image_format] * len(images)))
            self.rec.send_columns(f"{root}/{table}/policy", index, rr.Arrows2D.columns(
                origins=np.concatenate(origins), vectors=np.concatenate(vectors),
                colors=np.concatenate(colors)).partition([len(o) for o in origins]))
            self.rec.send_columns(f"{root}/{table}/stay", index, rr.Points2D.columns(
                positions=np.concatenate(stays)).partition([len(p) for p in stays]))

    def close(self) -> None:
        """Send what is buffered and close the agent's own stream."""
        self.flush()
        close_stream(self.rec, who=f"agent {self.agent}'s recording")
