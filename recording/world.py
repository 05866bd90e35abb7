"""The world's Rerun recording: what happens each tick and why, and the run's metrics per episode.

At time ``tick = t`` the viewer shows the state in which the agents decided tick ``t``: for each
agent, under ``world/agents/<id>`` (``recording.agent_entities``), its cell, its goal, the last
cells it came through, the step that brought it there, the move it announced and whose intent
it waited for; and who collided as a result (``world/collisions``, plus a warning in
``events``); under ``--arbitration pibt`` whose first choice was refused (``world/refused``) and
who pushed whom (``world/pushes``), and in a lifelong run the goals reached (``world/reached``),
the goals moving on to the next. The next tick shows where everybody ended up.

The negotiation is derived by the world, not reported by the agents: at tick ``t`` an agent that
reads intents and has not arrived waits for the answer of every neighbour that
``protocol.ranks.awaits_answer`` names, the rule ``learning.plan.awaited_into`` applies too. How each intent reached it (its own query, or relayed down the chain,
``agent.negotiation``) and whether it came in time is known only to the agent; the agents log
that themselves (``recording.agent``).

Per-episode metrics (``metrics/...``) are logged at each episode's end tick; see :data:`METRICS`.
Timelines are ``tick`` and ``episode``; static things (grid, walls, colours, labels, the key
``legend``) are logged once. Each agent is an entity of its own (from 16 agents on, each
group of 64), all of them sent in one call per flush. Agents and goals share a colour
(:func:`agent_colors`, one per agent, all different) and a label, the agent's id. With a learner
that reads the known map, one agent's map and planned path go with the world's ticks too
(``recording.known_map_view``). The blueprint
(``recording.session.blueprint``) opens on the ``episode`` timeline, where the view shows the
intents, waits and collisions of the whole episode at once.

Cost: everything is buffered, the per-tick entities, each episode's goals, metrics and event
lines alike, and sent with ``send_columns`` (one call per entity) every :data:`FLUSH_EVERY` ticks
or :data:`recording.columns.FLUSH_SECONDS` of wall time, whichever comes first, and at the end.
That makes a dozen calls a flush instead of a dozen a tick (what it costs:
``bench/recording_cost.py``, ``bench/recording_cpu.py``), and it bounds the memory the Rerun
SDK keeps per logging call (``recording.columns``). The world also sends what it holds before
each episode's row (:meth:`WorldViz.before_row`), so that a world killed outright loses no
episode it has a row for: a flush then spans one episode, and costs the Rerun SDK about 200
bytes of native memory per call for good (a dozen calls an episode).
"""

import sys
import time
from pathlib import Path

import numpy as np
import rerun as rr

from nnql_swarm.protocol.actions import MOVES
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.ranks import awaits_answer, priority_rank
from nnql_swarm.recording.agent_entities import (
    CROWDED_FROM, DISC, GOAL, INTENT, PATH, ROUTE, START, TRAIL, WAITS, EntityColumns, by_entity,
    crowded, owners, part_paths,
)
from nnql_swarm.recording.fading import BANDS, FRESH_STEPS, route_strips
from nnql_swarm.recording.columns import FlushClock, SeriesColumns, TextColumns, time_columns
from nnql_swarm.recording.jams import JAM_HALF, JAM_LINE, JamMap
from nnql_swarm.recording.shown import ca_learns, collision_bound, learns
from nnql_swarm.recording.sinks import close_stream
from nnql_swarm.recording.palette import (
    COLLISION_RED, PUSH_COLOUR, REACHED_COLOUR, WAIT_COLOUR, WALL_COLOUR, agent_colors,
)
from nnql_swarm.transport.runfiles import check_space
from nnql_swarm.world.engine import SwarmWorld, TickReport
from nnql_swarm.world.scenario import swarm_episode

APP_ID = "nnql-swarm"

GRID = "world/grid"
WALLS = "world/walls"
COLLISIONS = "world/collisions"
STUCK = "world/stuck"
CAPTION = "world/caption"
REFUSED = "world/refused"
PUSHES = "world/pushes"
REACHED = "world/reached"
JAMS = "world/jams"
EVENTS = "events"
LEGEND = "legend"

WALL_HALF = 0.2
"""Half the width of a wall's box outline; the outline is :data:`WALL_LINE` wide on each side
of it, so that the box is a solid block 0.88 of a cell wide."""
WALL_LINE = 0.24
GOAL_HALF = 0.42
"""Half the width of a goal's box, in cells; its outline's radius is :data:`GOAL_LINE`."""
GOAL_LINE = 0.07

def caption_room(config: SwarmConfig) -> float:
    """The room above the grid, in cells, that the world view leaves for its caption (the tick's
    episode and step): about as many pixels at any grid size, so that the caption's label never
    covers the grid's top line."""
    return 0.04 * max(config.width, config.height) + 0.6


def caption_y(config: SwarmConfig) -> float:
    """Where the caption stands: in the middle of the room above the grid."""
    return -0.5 - caption_room(config) / 2

STUCK_RING = 0.38 * np.stack([np.cos(np.linspace(0, 2 * np.pi, 17)),
                              np.sin(np.linspace(0, 2 * np.pi, 17))], axis=1).astype(np.float32)
"""The ring around an agent an episode ended short of its goal, about its cell's centre: round
the agent's disc (0.3), inside the cell, clear of the grid's lines."""

METRICS = {
    "metrics/arrived_share": "share of the agents on their goal when the episode ended (0 to 1)",
    "metrics/steps/over_shortest": "steps the agents took over their shortest paths "
                                   "(agent_steps / shortest_sum; 1 is the best possible)",
    "metrics/steps/shortest_path": "the reference of over_shortest: 1, every agent on a shortest path",
    "metrics/steps/smoothed": "over_shortest smoothed: an exponential moving average over "
                              "episodes (SMOOTHING), from the run's (or the resume's) first",
    "metrics/collisions/per_episode": "collisions in the episode (each colliding agent counts one)",
    "metrics/collisions/cumulative": "collisions since the run started",
    "metrics/steps/per_agent": "mean steps an agent took until it arrived (agent_steps / agents)",
    "metrics/steps/shortest_per_agent": "mean shortest path, start to goal (shortest_sum / agents)",
    "metrics/steps/episode": "ticks until every agent arrived, or max steps",
    "metrics/arrived": "agents on their goal when the episode ended",
    "metrics/reward_sum": "sum of every agent's DS and CA rewards in the episode",
    "metrics/reward_smoothed": "reward_sum smoothed as the steps ratio is (SMOOTHING)",
    "metrics/missed_intents": "intents that missed the tick deadline (counted as STAY)",
    "metrics/ticks_per_s": "wall-clock ticks per second of the world's clock in the episode",
    "metrics/negotiation/awaited_per_tick": "intents waited for per tick, all agents (world-derived)",
    "metrics/refused": "first choices the arbitration refused in the episode (--arbitration pibt)",
    "metrics/throughput": "goals reached a step in the episode (--tasks lifelong)",
}
"""Every per-episode series the world logs, with what it means (docs/recording.md repeats this)."""

SERIES_NAMES = {
    "metrics/arrived_share": "arrived (share of agents)",
    "metrics/steps/over_shortest": "steps / shortest path",
    "metrics/steps/shortest_path": "shortest path (1)",
    "metrics/steps/smoothed": "smoothed",
    "metrics/collisions/per_episode": "collisions in the episode",
    "metrics/collisions/cumulative": "collisions since the start",
    "metrics/steps/per_agent": "steps per agent",
    "metrics/steps/shortest_per_agent": "shortest path per agent",
    "metrics/steps/episode": "ticks in the episode",
    "metrics/arrived": "agents arrived",
    "metrics/reward_sum": "reward sum",
    "metrics/reward_smoothed": "smoothed",
    "metrics/missed_intents": "missed intents",
    "metrics/ticks_per_s": "ticks per second",
    "metrics/negotiation/awaited_per_tick": "intents awaited per tick",
    "metrics/refused": "first choices refused",
    "metrics/throughput": "goals a step",
}
"""What each series is called in the plots' legends."""

SERIES_COLOURS = {
    "metrics/arrived_share": (0, 130, 60),
    "metrics/steps/over_shortest": (120, 170, 225),
    "metrics/steps/smoothed": (0, 60, 140),
    "metrics/steps/shortest_path": (150, 150, 150),
    "metrics/collisions/per_episode": (230, 40, 40),
    "metrics/collisions/cumulative": (120, 20, 20),
    "metrics/reward_sum": (230, 190, 120),
    "metrics/reward_smoothed": (150, 90, 0),
}

SMOOTHING = 0.1
"""The weight of each new episode in the smoothed curves (the steps ratio, the reward): a memory
of about ten episodes."""

INTENT_SCALE = 0.7
"""An announced move's arrow, in cells: short of the next cell, so that arrows in a row do not
join."""

TRAIL_LENGTH = 10
"""How many cells of each agent's recent path the trail shows."""

ROW_FLUSH_S = 2.0
"""How long the world waits at most, before an episode's row, for the episode to reach the
recording's file (:meth:`WorldViz.before_row`). Not 0: without the wait a row could reach
``episodes.csv`` while its episode was still on its way, and a ``kill -9`` then lost that
episode from the recording (the resume does not play it again). The wait costs nothing
measurable: the default run of 60 episodes took 5.2 and 4.9 s with it, 5.3 and 5.0 s without."""
FLUSH_EVERY = 2000
"""The most ticks buffered before a flush (which also comes after ``FLUSH_SECONDS``); a flush
costs a dozen logging calls, however few ticks it sends."""

def with_alpha(colors: np.ndarray, alpha: int) -> np.ndarray:
    return np.concatenate([colors, np.full((len(colors), 1), alpha, dtype=np.uint8)], axis=1)


def negotiation_pairs(config: SwarmConfig, positions: np.ndarray, arrived: np.ndarray,
                      ticks: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, asker, asked)``: at tick ``ticks[t]`` agent ``asker`` waits for ``asked``'s intent
    (``positions`` ``(T, n, 2)``, ``arrived`` ``(T, n)``: as each tick started), in the order of
    ``t``, then ``asker``, then ``asked``. Only the pairs within the interaction radius
    (Chebyshev, which ``protocol.ranks.in_reach`` requires) are put to the rule, so that a tick
    of n agents costs about n times its neighbours, not n squared rule calls."""
    n, radius, meet = config.n_agents, config.interaction_radius, config.meet_only
    found: tuple[list[int], list[int], list[int]] = ([], [], [])
    if config.algo in NEGOTIATING_ALGOS:
        cells = np.asarray(positions, dtype=np.int32)
        parked = np.asarray(arrived, dtype=bool) & (not config.step_aside)
        for t, tick in enumerate(np.asarray(ticks).tolist()):
            x, y = cells[t, :, 0], cells[t, :, 1]
            near = np.abs(x[:, None] - x[None, :]) <= radius
            near &= np.abs(y[:, None] - y[None, :]) <= radius
            np.fill_diagonal(near, False)
            near[parked[t]] = False  # an agent parked on its goal waits for nobody
            asker, asked = np.nonzero(near)
            if not len(asker):
                continue
            ranks = [priority_rank(i, tick, n) for i in range(n)]
            xy, stays = cells[t].tolist(), parked[t].tolist()
            for i, j in zip(asker.tolist(), asked.tolist()):
                (x, y), (jx, jy) = xy[i], xy[j]
                if awaits_answer(ranks[i], ranks[j], x, y, jx, jy, radius, meet, False, stays[j]):
                    found[0].append(t)
                    found[1].append(i)
                    found[2].append(j)
    ticks_at, askers, asked_ones = (np.array(column, dtype=np.int64) for column in found)
    return ticks_at, askers, asked_ones


def legend(config: SwarmConfig) -> str:
    """The recording's key (``legend``, a markdown document): what the world view and the heat
    maps draw, and what their colours mean."""
    walls = " Dark blocks are walls." if config.obstacle_density > 0 else ""
    shared = ("" if not learns(config) else
              "The agents learn into one shared table: the heat maps show it once."
              if config.shared else "Each agent has its own tables: one tab per agent (the "
              f"first {min(config.n_agents, 8)}).")
    waits = ("Black arrows from an agent to a neighbour: it waited for that neighbour's "
             "announced move before deciding (negotiation)." if config.algo in NEGOTIATING_ALGOS
             else f"{config.algo} agents do not negotiate: they wait for nobody.")
    arbitration = ("\nPriority inheritance settles the moves (`--arbitration pibt`): a thin red "
                   "arrow is a first choice refused (towards the cell wanted), a thick purple one "
                   "goes from an agent to the one it pushed on (that one left its cell against "
                   "its first choice): follow them for the chains of inheritance."
                   if config.arbitration == "pibt" else "")
    lifelong = ("\nLifelong tasks: a yellow disc is a goal reached; the agent's box moves on to "
                "its next goal at once. The first curve is the throughput, goals a step."
                if config.lifelong else "")
    return f"""**World** ({config.width} x {config.height}, {config.n_agents} agents).
Discs are agents, labelled with their id; the box with the same id and colour is that agent's
goal. Every agent has a colour of its own.{walls}
On the `episode` timeline (the one the viewer opens on) the view shows a whole episode: {moves(config)}
the collisions (red discs), and the agents where the episode left them; a small dot in an
agent's colour is where it started, a red ring around an agent the episode left short of its
goal, and red shading where agents on their way waited (the traffic jams: the deeper the red,
the more steps waited there). On the `tick` timeline it shows one tick (the
caption above the grid names its episode and step): where each agent stood, the move it
announced, its last {TRAIL_LENGTH} cells.
{waits}{arbitration}{lifelong}
{following(config)}

**Learning curves** run against episodes: the share of agents that arrived, the steps they took
over their shortest paths (1 is perfect), collisions (each agent in one counts one), the
reward (pale: each episode; dark: smoothed over about ten episodes){explored(config)}.

{tables(config)}
{shared}
"""


def moves(config: SwarmConfig) -> str:
    """What the ``episode`` timeline draws of the agents' moves."""
    if crowded(config.n_agents):
        return (f"each agent's path, drawn at the episode's end (a line in its colour: opaque "
                f"for its last {FRESH_STEPS} steps, the steps before them in {BANDS} bands, the "
                f"earlier the fainter; from {CROWDED_FROM} agents on the moves and waits are on "
                f"the `tick` timeline only),")
    return ("every move announced (thick arrows in the agent's colour), every wait (below), "
            "the path each agent took (a thin line in its colour),")


def following(config: SwarmConfig) -> str:
    """What the key says of picking an agent: one entity each, or groups of many agents."""
    from nnql_swarm.recording.agent_entities import GROUP_SIZE, GROUPED_FROM

    if config.n_agents < GROUPED_FROM:
        return ("Each agent is an entity of its own, `world/agents/<id>` (its disc, trail, path, "
                "moves, waits, goal and start): click its disc to select it, or open the "
                "blueprint panel (top left) to hide the others and follow one.")
    return (f"From {GROUPED_FROM} agents on the agents go in groups of {GROUP_SIZE} (so that "
            f"the web viewer draws them on the grid): `world/agents/group-<k>` holds agents "
            f"{GROUP_SIZE}k to {GROUP_SIZE}k + {GROUP_SIZE - 1}, each of them an instance of "
            f"its parts; click a disc to select that agent, or hide a group or a part (its "
            f"routes, its goals) in the blueprint panel (top left).")


def explored(config: SwarmConfig) -> str:
    """What the key says of the exploration curve."""
    if not learns(config):
        return ""
    tables = "Q_DS and Q_CA" if ca_learns(config) else "Q_DS"
    return (f", and the share of the states of {tables} met so far (exploration: every "
            f"{config.random_step}th action is random, {100 / config.random_step:g} % "
            f"throughout, and these curves say how much of the tables that reached)")


def tables(config: SwarmConfig) -> str:
    """The key's paragraphs on the known map and the Q-tables, for this run's learners."""
    if not learns(config):
        return f"**{config.algo}** agents plan; they learn no tables."
    if not ca_learns(config):
        rest_ca = (" **Q_CA** is not shown: with the shield, negotiating agents do not collide, "
                   f"and the table starts at {collision_bound(config):g}, the value of never "
                   "colliding, so it has nothing to learn.")
    else:
        rest_ca = ""
    scale = ("the colour is the best action's value, dark purple (low) to yellow (high), on a "
             "fixed scale: ")
    rest = ("Light grey: an entry still above anything it can learn, i.e. on its optimistic "
            "start, not yet explored. Blank: never updated. Arrows: the best move; a dot: STAY.")
    ca = (f"Q_CA 0 to {collision_bound(config):g}, the value of never colliding (dark: a "
          f"neighbour there led to collisions)")
    if config.ds_state == "goal":
        return (f"**Heat maps**: one pixel per offset of the goal (Q_DS) or of a neighbour (Q_CA)"
                f" from the agent, the red square in the middle; {scale}Q_DS 0 to the goal "
                f"reward {config.goal_reward:g} (bright: close to the goal), {ca}. {rest}"
                f"{rest_ca}")
    state = ("the next cell of its planned path" if config.ds_state == "waypoint"
             else "the moves that bring it nearer its goal")
    return (f"**Known map** (one agent's, `--map-agent`): the walls it has seen (dark blocks) "
            f"and those it has not (pale outlines), the parked agents it plans around (grey), "
            f"and its planned path to its goal on the map it knows (a line in its colour; on the "
            f"`episode` timeline the last it planned in the episode), unknown cells taken as "
            f"free.\n\n"
            f"**Q_DS** is read on that map: its state is {state}, so it is a table, one row per "
            f"state: the best move, its value (up to {config.goal_reward:g}, the goal reward), "
            f"and whether that move follows the planned path. " + (
                rest_ca.strip() if rest_ca else
                f"**Q_CA heat map**: one pixel per offset of a neighbour from the agent, the red "
                f"square in the middle; {scale}{ca}. {rest}"))


class WorldViz:
    """Logs a swarm run, tick by tick, into one Rerun recording stream.

    :meth:`log_tick` only keeps references to the tick's state (plain tuples, a few
    microseconds: it runs on the world's main thread at every tick, beside the negotiation);
    :meth:`flush` turns every buffered tick into arrays at once, computes their geometry and
    sends one chunk per entity.
    """

    def __init__(self, config: SwarmConfig, stream: rr.RecordingStream,
                 flush_every: int = FLUSH_EVERY, collisions_before: int = 0,
                 map_agent: int | None = 0, files: Path | None = None) -> None:
        """``collisions_before``: the collisions of the episodes a resumed run already has;
        ``map_agent``: the agent whose known map and planned path the recording shows
        (``recording.known_map_view``; None: nobody's); ``files``: the folder the stream's
        file is written to (None: streamed to a viewer only)."""
        self.config = config
        self.rec = stream
        self.files = files
        self.row_flush_s = ROW_FLUSH_S  # 0 where a viewer is streamed to: no wait for it
        self.flush_failed = False  # said once
        self.clock = FlushClock(flush_every)
        n = config.n_agents
        self.colors = agent_colors(n)
        self.cumulative_collisions = collisions_before
        self._smoothed: dict[str, float] = {}  # the smoothed curves' moving averages
        self.next_tick = 0
        self._before: tuple | None = None  # cells at the start of the next tick
        self._arrived: tuple = (False,) * n
        self._trail = np.zeros((n, TRAIL_LENGTH, 2), dtype=np.float32)  # before the buffer
        self._trail_episode = -1  # the episode whose trails self._trail continues
        self._goals_episode = -1
        self._episode_clock: float | None = None
        self._episode_first_tick = 0
        self._awaited: dict[int, int] = {}  # per episode, until its metrics are sent
        self._ended: list[tuple[int, int, int]] = []  # tick, episode, steps: awaited not yet sent
        # The buffered ticks, one entry each: tick, episode, whether anyone could move, every
        # agent's cell and whether it had arrived at the tick's start, the actions, who collided.
        self._buffer: list[tuple] = []
        self._starts: dict[int, np.ndarray] = {}  # the buffered episodes' start cells
        self._goals: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # goals, starts
        self._stuck: list[tuple[int, int, np.ndarray]] = []  # at each episode's end
        self._metrics = SeriesColumns()
        self._events = TextColumns(EVENTS)
        self._goal_cells: list = []  # the current episode's goals
        self._starts_of: dict[int, np.ndarray] = {}  # the current episode's starts
        self._refused = 0  # first choices refused in the current episode (--arbitration pibt)
        self._reached: list[tuple[int, int, np.ndarray]] = []  # lifelong: goals reached
        self._jams = JamMap(config.width, config.height)
        self._jam_maps: list[tuple[int, int, np.ndarray, np.ndarray]] = []  # per episode's end
        # Crowded runs: every agent's cells this episode, and the routes to send (empty at an
        # episode's start, the episode's at its end).
        self._route: list[tuple] = []
        self._routes: list[tuple[int, int, np.ndarray | None]] = []
        self._log_static()
        self.known_map = None
        if map_agent is not None and 0 <= map_agent < n:
            from nnql_swarm.recording.known_map_view import KnownMapViz, shows_known_map

            if shows_known_map(config):
                self.known_map = KnownMapViz(config, map_agent, stream, self.colors[map_agent])

    @staticmethod
    def to_file(config: SwarmConfig, path: Path) -> "WorldViz":
        stream = rr.RecordingStream(APP_ID, recording_id=config.run_id)
        stream.save(str(path))
        return WorldViz(config, stream)

    def _log_static(self) -> None:
        c, rec = self.config, self.rec
        xs = np.arange(c.width + 1) - 0.5
        ys = np.arange(c.height + 1) - 0.5
        lines = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
        # radius in UI points (negative): lines 2 points wide at any grid size
        rec.log(GRID, rr.LineStrips2D(lines, colors=[90, 90, 90], radii=-1.0, draw_order=2.0),
                static=True)
        walls = c.walls()
        if len(walls):
            # A box's outline drawn with a line wider than the box fills it: a block that leaves
            # a rim of the cell, where the grid's lines stay visible (each box its half-size).
            rec.log(WALLS, rr.Boxes2D(centers=walls.astype(np.float32),
                                      half_sizes=np.full(walls.shape, WALL_HALF, np.float32),
                                      colors=[WALL_COLOUR], radii=WALL_LINE, draw_order=1.0),
                    static=True)
        for path, agents in owners(c.n_agents):
            colours, labels = self.colors[agents], [str(i) for i in agents]
            rec.log(f"{path}/{DISC}", rr.Points2D.from_fields(
                colors=colours, labels=labels, radii=0.3, show_labels=True, draw_order=30.0),
                static=True)
            rec.log(f"{path}/{GOAL}", rr.Boxes2D.from_fields(
                colors=colours, labels=labels, show_labels=True, radii=GOAL_LINE, draw_order=10.0),
                static=True)
            rec.log(f"{path}/{TRAIL}", rr.LineStrips2D.from_fields(
                colors=with_alpha(colours, 110), radii=0.06, draw_order=15.0), static=True)
            rec.log(f"{path}/{PATH}", rr.LineStrips2D.from_fields(
                colors=with_alpha(colours, 90), radii=0.05, draw_order=14.0), static=True)
            if crowded(c.n_agents):  # colours per band (recording.fading)
                rec.log(f"{path}/{ROUTE}", rr.LineStrips2D.from_fields(
                    radii=0.12, draw_order=14.0), static=True)
            rec.log(f"{path}/{INTENT}", rr.Arrows2D.from_fields(
                colors=colours, radii=0.09, draw_order=40.0), static=True)
            rec.log(f"{path}/{WAITS}", rr.Arrows2D.from_fields(
                colors=[WAIT_COLOUR], radii=0.045, draw_order=45.0), static=True)
            rec.log(f"{path}/{START}", rr.Points2D.from_fields(
                colors=with_alpha(colours, 150), radii=0.12, draw_order=12.0), static=True)
        rec.log(LEGEND, rr.TextDocument(legend(c), media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log(COLLISIONS, rr.Points2D.from_fields(colors=[COLLISION_RED], radii=0.5,
                                                    draw_order=20.0), static=True)
        rec.log(STUCK, rr.LineStrips2D.from_fields(colors=[COLLISION_RED], radii=0.045,
                                                   draw_order=25.0), static=True)
        rec.log(REFUSED, rr.Arrows2D.from_fields(colors=[COLLISION_RED], radii=0.05,
                                                 draw_order=42.0), static=True)
        rec.log(PUSHES, rr.Arrows2D.from_fields(colors=[PUSH_COLOUR], radii=0.07,
                                                draw_order=43.0), static=True)
        rec.log(REACHED, rr.Points2D.from_fields(colors=[REACHED_COLOUR], radii=0.22,
                                                 draw_order=11.0), static=True)
        rec.log(JAMS, rr.Boxes2D.from_fields(radii=JAM_LINE, draw_order=2.0), static=True)
        rec.log(CAPTION, rr.Points2D.from_fields(colors=[[90, 90, 90]], radii=0.01,
                                                 show_labels=True, draw_order=50.0), static=True)
        for path in METRICS:
            colour = SERIES_COLOURS.get(path)
            rec.log(path, rr.SeriesLines(names=SERIES_NAMES[path], widths=2.0,
                                         colors=None if colour is None else [colour]),
                    static=True)

    def log_tick(self, world: SwarmWorld, report: TickReport) -> None:
        """Log one applied tick (call it right after ``world.apply``)."""
        c = self.config
        if self._episode_clock is None:
            self._episode_clock = time.perf_counter()
            self._episode_first_tick = report.tick
            self._events.add(report.tick, report.episode,
                             f"run {c.run_id}: {c.n_agents} {c.algo} agents on a {c.width}x"
                             f"{c.height} grid, {c.episodes} episodes of at most {c.max_steps} "
                             f"steps, seed {c.seed}; from episode {report.episode}", "INFO")
        before = self._before
        if before is None:  # the first tick seen: it starts an episode (fresh run or resume)
            before = tuple(map(tuple, swarm_episode(c.seed, report.episode, c.width, c.height,
                                                    c.n_agents, c.obstacle_density, c.map_rows,
                                                    c.scenario
                                                    ).starts.tolist()))
        starts = report.episode != self._goals_episode
        if starts:
            self._start_episode(report)
        if self.known_map is not None:
            agent = self.known_map.agent
            self.known_map.observe(report.tick, report.episode, starts, before, self._arrived,
                                   self._goal_cells[agent])
        self._buffer.append((report.tick, report.episode, report.moved, before, self._arrived,
                             report.actions, report.collided,
                             report.tick - self._episode_first_tick,
                             report.wanted or report.actions))
        self._refused += sum(w != a for w, a in zip(report.wanted, report.actions))
        if report.reached:  # lifelong: goals reached, and the next ones from the next tick
            self._reached.append((report.tick + 1, report.episode, np.array(
                [self._goal_cells[i] for i in report.reached], np.float32).reshape(-1, 2)))
            self._goal_cells = [list(cell) for cell in report.goals]
            if report.episode_row is None:
                self._goals.append((report.tick + 1, report.episode,
                                    np.array(report.goals, np.float32),
                                    self._starts_of[report.episode]))
        if report.collided:
            step = f"step {world.step}" if report.moved else "end"
            self._events.add(report.tick, report.episode,
                             f"{step}: collision of agents "
                             f"{', '.join(map(str, report.collided))}", "WARN")
        if report.moved:
            self._jams.add(before, world.cells,
                           (True,) * c.n_agents if c.lifelong else
                           tuple(not home for home in self._arrived))
        if crowded(c.n_agents):
            self._route.append(before)
        if report.episode_row is not None:  # its end tick: nobody moves, as the episode left them
            self._jam_maps.append((report.tick, report.episode, *self._jams.take()))
            if crowded(c.n_agents):
                self._routes.append((report.tick, report.episode,
                                     np.array(self._route, np.float32)))
            short = [cell for cell, home in zip(before, self._arrived)
                     if not home and not c.lifelong]  # lifelong: everyone is on its way
            self._stuck.append((report.tick, report.episode,
                                np.array(short, np.float32).reshape(-1, 2)))
        self._before, self._arrived = world.cells, world.arrived_flags
        self.next_tick = report.tick + 1
        if report.episode_row is not None:
            self._end_episode(report, report.episode_row)
        if self.clock.due(len(self._buffer)):
            self.flush()

    def _start_episode(self, report: TickReport) -> None:
        self._goals_episode = report.episode
        c = self.config
        episode = swarm_episode(c.seed, report.episode, c.width, c.height, c.n_agents,
                                c.obstacle_density, c.map_rows, c.scenario)
        self._starts[report.episode] = episode.starts.astype(np.float32)
        self._starts_of = {report.episode: self._starts[report.episode]}
        self._goals.append((report.tick, report.episode, episode.goals.astype(np.float32),
                            episode.starts.astype(np.float32)))
        self._stuck.append((report.tick, report.episode, np.zeros((0, 2), np.float32)))
        self._jam_maps.append((report.tick, report.episode, np.zeros((0, 2), np.float32),
                               np.zeros((0, 4), np.uint8)))
        self._route = []
        if crowded(c.n_agents):
            self._routes.append((report.tick, report.episode, None))
        self._goal_cells = episode.goals.tolist()

    def _end_episode(self, report: TickReport, row: dict) -> None:
        n, started = self.config.n_agents, self._episode_clock
        assert started is not None, "an episode ends after its first tick"
        now = time.perf_counter()
        ticks = report.tick + 1 - self._episode_first_tick
        rate = ticks / max(now - started, 1e-9)
        self._episode_clock, self._episode_first_tick = now, report.tick + 1
        self.cumulative_collisions += row["collisions"]
        ratio = row["agent_steps"] / max(row["shortest_sum"], 1)
        values = {
            "metrics/arrived_share": row["arrived"] / n,
            "metrics/steps/over_shortest": ratio,
            "metrics/steps/smoothed": self._smooth("metrics/steps/smoothed", ratio),
            "metrics/steps/shortest_path": 1.0,
            "metrics/collisions/per_episode": row["collisions"],
            "metrics/collisions/cumulative": self.cumulative_collisions,
            "metrics/steps/per_agent": row["agent_steps"] / n,
            "metrics/steps/shortest_per_agent": row["shortest_sum"] / n,
            "metrics/steps/episode": row["steps"],
            "metrics/arrived": row["arrived"],
            "metrics/reward_sum": row["reward_sum"],
            "metrics/reward_smoothed": self._smooth("metrics/reward_smoothed", row["reward_sum"]),
            "metrics/missed_intents": row["missed_intents"],
            "metrics/ticks_per_s": rate,
        }
        if self.config.arbitration == "pibt":
            values["metrics/refused"] = self._refused
        if self.config.lifelong:
            values["metrics/throughput"] = row["throughput"]
        self._refused = 0
        for path, value in values.items():
            self._metrics.add(path, report.tick, report.episode, value)
        self._ended.append((report.tick, report.episode, max(row["steps"], 1)))
        done = (f"{row['goals']} goals reached ({row['throughput']:.2f} a step)"
                if self.config.lifelong else f"{row['arrived']}/{n} arrived")
        self._events.add(report.tick, report.episode,
                         f"{row['steps']} steps, {done}, "
                         f"{row['collisions']} collisions, {row['missed_intents']} missed, "
                         f"{rate:.0f} ticks/s, reward {row['reward_sum']:.0f}", "INFO")

    def _smooth(self, path: str, value: float) -> float:
        """The next value of an exponential moving average (:data:`SMOOTHING`) from the run's
        (or the resume's) first episode."""
        before = self._smoothed.get(path)
        self._smoothed[path] = value if before is None else \
            (1 - SMOOTHING) * before + SMOOTHING * value
        return self._smoothed[path]

    def flush(self) -> None:
        """Send everything buffered: the ticks' geometry computed at once, one call per entity."""
        self.clock.flushed()
        if self._goals:
            g_ticks, g_episodes, goals, starts = zip(*self._goals)
            self._goals = []
            n, k = self.config.n_agents, len(goals)
            order, lengths = by_entity(np.repeat(np.arange(k), n), np.tile(np.arange(n), k), k, n)
            columns = EntityColumns(time_columns(g_ticks, g_episodes), k)
            centers = np.concatenate(goals)[order]
            columns.add(part_paths(n, GOAL), rr.Boxes2D.columns(
                centers=centers, half_sizes=np.full(centers.shape, GOAL_HALF, np.float32)
            ).partition(lengths))
            columns.add(part_paths(n, START), rr.Points2D.columns(
                positions=np.concatenate(starts)[order]).partition(lengths))
            columns.send(self.rec)
        if self._stuck:
            s_ticks, s_episodes, cells = zip(*self._stuck)
            self._stuck = []
            rings = np.concatenate(cells)[:, None, :] + STUCK_RING[None]
            self.rec.send_columns(STUCK, time_columns(s_ticks, s_episodes), rr.LineStrips2D.columns(
                strips=rings).partition([len(c) for c in cells]))
        if self._jam_maps:
            j_ticks, j_episodes, centres, colours = zip(*self._jam_maps)
            self._jam_maps = []
            every = np.concatenate(centres)
            self.rec.send_columns(JAMS, time_columns(j_ticks, j_episodes), rr.Boxes2D.columns(
                centers=every, half_sizes=np.full(every.shape, JAM_HALF, np.float32),
                colors=np.concatenate(colours)).partition([len(c) for c in centres]))
        if self._routes:
            self._send_routes()
        if self._reached:
            r_ticks, r_episodes, cells = zip(*self._reached)
            self._reached = []
            self.rec.send_columns(REACHED, time_columns(r_ticks, r_episodes), rr.Points2D.columns(
                positions=np.concatenate(cells)).partition([len(c) for c in cells]))
        if self._buffer:
            self._send_ticks()
        for tick, episode, steps in self._ended:  # every tick of theirs is counted now
            self._metrics.add("metrics/negotiation/awaited_per_tick", tick, episode,
                              self._awaited.pop(episode, 0) / steps)
        self._ended = []
        self._metrics.send(self.rec)
        self._events.send(self.rec)
        if self.known_map is not None:
            self.known_map.flush()

    def _send_ticks(self) -> None:
        k, n = len(self._buffer), self.config.n_agents
        rec = self.rec
        tick_list, episode_list, moved, before, arrived_then, actions, collided, steps, wanted = \
            zip(*self._buffer)
        self._buffer = []
        ticks, episodes = np.array(tick_list, dtype=np.int64), np.array(episode_list, np.int64)
        positions = np.array(before, dtype=np.int64)  # (k, n, 2): the cells each tick started from
        index = time_columns(ticks, episodes)
        cells = positions.astype(np.float32)
        rec.send_columns(CAPTION, index, rr.Points2D.columns(
            positions=np.tile(np.array([[(self.config.width - 1) / 2, caption_y(self.config)]],
                                       np.float32), (k, 1)),
            labels=[f"episode {e}, {f'step {s}' if m else 'its end'} (tick {t})"
                    for e, s, t, m in zip(episode_list, steps, tick_list, moved)]))
        # Every agent's parts, entity by entity (recording.agent_entities), in one call.
        parts = EntityColumns(index, k)
        order, lengths = by_entity(np.repeat(np.arange(k), n), np.tile(np.arange(n), k), k, n)
        flat = cells.reshape(-1, 2)[order]
        parts.add(part_paths(n, DISC), rr.Points2D.columns(positions=flat).partition(lengths))
        moves = (MOVES[np.array(actions, dtype=np.int64)] * INTENT_SCALE).astype(np.float32)
        parts.add(part_paths(n, INTENT), rr.Arrows2D.columns(
            origins=flat, vectors=moves.reshape(-1, 2)[order]).partition(lengths))
        trails = np.concatenate([self._trails(cells[first:last], int(episodes[first]))
                                 for first, last in episode_spans(episodes)])
        trails = trails.reshape(-1, TRAIL_LENGTH, 2)[order]
        parts.add(part_paths(n, TRAIL), rr.LineStrips2D.columns(strips=trails).partition(lengths))
        parts.add(part_paths(n, PATH), rr.LineStrips2D.columns(  # the step that led here
            strips=np.ascontiguousarray(trails[:, -2:])).partition(lengths))

        t, asker, asked = negotiation_pairs(self.config, positions,
                                            np.array(arrived_then, dtype=bool), ticks)
        kept = np.array(moved, dtype=bool)[t]
        t, asker, asked = t[kept], asker[kept], asked[kept]
        for episode, count in zip(*np.unique(episodes[t], return_counts=True)):
            self._awaited[int(episode)] = self._awaited.get(int(episode), 0) + int(count)
        start, end = cells[t, asker], cells[t, asked]
        gap = end - start
        unit = gap / np.maximum(np.linalg.norm(gap, axis=-1, keepdims=True), 1e-6)
        order, lengths = by_entity(t, asker, k, n)
        parts.add(part_paths(n, WAITS), rr.Arrows2D.columns(  # WAIT_COLOUR, logged once (static)
            origins=(start + unit * 0.2)[order], vectors=(gap - unit * 0.4)[order],
        ).partition(lengths))
        parts.send(rec)

        if self.config.arbitration == "pibt":
            self._send_arbitration(index, cells, np.array(actions, np.int64),
                                   np.array(wanted, np.int64), np.array(moved, dtype=bool))

        hit = np.zeros((k, n), dtype=bool)
        for row, agents in enumerate(collided):
            hit[row, list(agents)] = True
        hit_t, hit_agent = np.nonzero(hit)
        rec.send_columns(COLLISIONS, index, rr.Points2D.columns(
            positions=cells[hit_t, hit_agent]).partition(hit.sum(axis=1)))

    def _send_routes(self) -> None:
        """Each agent's path of each episode in bands faded by age (``recording.fading``), at the
        episode's end tick; nothing from its start tick on."""
        n = self.config.n_agents
        ticks, episodes, routes = zip(*self._routes)
        self._routes = []
        rows, agents, strips, alphas = [], [], [], []
        for row, cells in enumerate(routes):
            if cells is None:
                continue
            who, these, alpha = route_strips(cells)
            rows.append(np.full(len(who), row))
            agents.append(who)
            alphas.append(alpha)
            strips += these
        k = len(routes)
        row_of = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        agent_of = np.concatenate(agents) if agents else np.zeros(0, np.int64)
        order, lengths = by_entity(row_of, agent_of, k, n)
        colours = np.zeros((len(strips), 4), np.uint8)
        if strips:
            colours[:, :3] = self.colors[agent_of]
            colours[:, 3] = np.concatenate(alphas)
        columns = EntityColumns(time_columns(ticks, episodes), k)
        columns.add(part_paths(n, ROUTE), rr.LineStrips2D.columns(
            strips=[strips[i] for i in order], colors=colours[order]).partition(lengths))
        columns.send(self.rec)

    def _send_arbitration(self, index, cells: np.ndarray, actions: np.ndarray,
                          wanted: np.ndarray, moved: np.ndarray) -> None:
        """Priority inheritance seen (``--arbitration pibt``), ``(k, n)`` ticks and agents: a thin
        red arrow where an agent's first choice was refused (towards the cell it wanted), and
        a thick dark one from each agent that pushed another (it took the cell of one that left
        it against its first choice) to the agent it pushed: the chains of inheritance."""
        refused = (wanted != actions) & moved[:, None]
        t, agent = np.nonzero(refused)
        self.rec.send_columns(REFUSED, index, rr.Arrows2D.columns(
            origins=cells[t, agent], vectors=(MOVES[wanted[t, agent]] * 0.45).astype(np.float32),
        ).partition(refused.sum(axis=1)))
        ends = cells + MOVES[actions].astype(np.float32)  # where each agent went
        pushes: list[np.ndarray] = []
        for row in range(len(cells)):
            left = {tuple(cell): i for i, cell in enumerate(cells[row].tolist())
                    if refused[row, i]}
            found = [(i, left[tuple(cell)]) for i, cell in enumerate(ends[row].tolist())
                     if tuple(cell) in left and left[tuple(cell)] != i]
            pushes.append(np.array(found, np.int64).reshape(-1, 2))
        counts = [len(p) for p in pushes]
        rows = np.repeat(np.arange(len(cells)), counts)
        pairs = np.concatenate(pushes) if pushes else np.zeros((0, 2), np.int64)
        start, end = cells[rows, pairs[:, 0]], cells[rows, pairs[:, 1]]
        self.rec.send_columns(PUSHES, index, rr.Arrows2D.columns(
            origins=start, vectors=(end - start) * 0.8).partition(counts))

    def _trails(self, cells: np.ndarray, episode: int) -> np.ndarray:
        """``(k, n, TRAIL_LENGTH, 2)``: at each of an episode's ticks ``cells`` ``(k, n, 2)``, the
        last TRAIL_LENGTH cells each agent started a tick from (its start cell before them)."""
        if episode != self._trail_episode:
            self._trail[:] = self._starts.pop(episode)[:, None, :]
            self._trail_episode = episode
        history = np.concatenate([self._trail, cells.transpose(1, 0, 2)], axis=1)
        windows = np.lib.stride_tricks.sliding_window_view(history, TRAIL_LENGTH, axis=1)
        self._trail = history[:, -TRAIL_LENGTH:].copy()
        return np.ascontiguousarray(windows[:, 1:].transpose(1, 0, 3, 2))

    def before_row(self) -> None:
        """Send the episode that just ended on its way to the recording's file before its row
        is written (``world.world_node``): a world killed after the row leaves its episodes in its
        part, which the next ``--resume`` merges, and the resumed world records from the row
        on, so that every episode is recorded. Waits for the file at most
        :data:`ROW_FLUSH_S` (not for a viewer, where one is streamed to). A file that could
        not be written for want of space stops the run as any of its files would (the
        OSError of ``transport.runfiles.check_space``): the row is not written, and the run
        resumes from the episode before, every episode recorded once. Else the run goes on."""
        self.flush()
        try:
            self.rec.flush(timeout_sec=self.row_flush_s)
        except Exception as error:  # noqa: BLE001 - as sinks.close_stream: the run goes on
            said, self.flush_failed = self.flush_failed, True
            if self.files is not None:
                check_space(self.files)
            if not said:
                print(f"rerun: could not flush the recording: {error} (said once)",
                      file=sys.stderr)

    def close(self) -> None:
        self.flush()
        close_stream(self.rec, quiet=self.flush_failed)



def episode_spans(episodes: np.ndarray) -> list[tuple[int, int]]:
    """``[(first, last), ...]``: the index ranges of the runs of equal values in ``episodes``."""
    cuts = (np.flatnonzero(np.diff(episodes)) + 1).tolist()
    return list(zip([0, *cuts], [*cuts, len(episodes)]))
