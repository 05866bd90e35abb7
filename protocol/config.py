"""The configuration of a swarm run, shared by the world, the agents and the launcher.

The launcher resolves it once, writes it to ``<out>/config.json``, and hands the same values to
every process, so that a distributed run and an in-process run of one config are the same run.
"""

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field, fields
from functools import cached_property
from typing import Any

import numpy as np

from nnql_swarm.protocol.actions import VIEW_RADIUS
from nnql_swarm.protocol.keys import validate_run_id
from nnql_swarm.protocol.keys import MAX_TICK
from nnql_swarm.protocol.messages import MAX_AGENTS, MAX_GRID, MAX_REWARD
from nnql_swarm.protocol.ranks import WAIT_RULES
from nnql_swarm.protocol.ranks import priority_rank  # noqa: F401 (the nodes import it from here)
from nnql_swarm.protocol.walls import MAX_DENSITY, layout, wall_count

ALGOS = ("nnql", "ql", "nnql-dir", "daql", "oracle")
"""nnQL (the paper), plain QL, nnQL whose neighbour state also holds the announced move, Double
Action Q-learning (a baseline), and the oracle: a reference planner (PIBT, ``world.pibt``; not a
lower bound, which ``shortest_sum`` is; in-process only)."""
NEGOTIATING_ALGOS = ("nnql", "nnql-dir")
DS_STATE_NAMES = ("goal", "waypoint", "progress")
DS_REWARD_NAMES = ("euclid", "path", "flat")
"""Destination seeking's state and reward (``learning.learner``: ``DS_STATES``, ``DS_REWARDS``)."""
MAX_LOOKAHEAD = 3
ON_TARGET = ("park", "step-aside")
"""What an agent on its goal does (``world.rules``): parks there for good (the paper's reading)
or stays unless it has to make way (the field's)."""
TASKS = ("one-shot", "lifelong")
"""What an agent does on reaching its goal (``world.tasks``): nothing more this episode (one goal
each, the episode over when all are home), or it is given a new one at once, and the episode runs
its ``max_steps`` (the field's lifelong setting, POGEMA's ``on_target: restart``)."""
MAX_LIFELONG_STEPS = 4096
"""The longest lifelong episode: every agent's goals are drawn for it ahead (one per step at
most, ``world.tasks``)."""
ARBITRATIONS = ("paper", "pibt")
"""How the world settles a tick's moves (``world.rules``): everyone's one intent applied at once,
colliding moves blocked and counted (the paper's), or priority inheritance (PIBT, with LaCAM's
swap; ``world.pibt.plan``) over each agent's announced order of its moves, so that nobody
collides and an agent whose first choice is refused earns no collision-avoidance reward."""

START_S_PER_AGENT = 1.0
"""The start-up a swarm is given per agent, where that is longer than a fixed wait: the world
waits so long for every agent to come alive, and an agent to see every other (spawned agents
import in parallel, slowly where they outnumber the cores: ``bench/scale.py --agents 128``)."""


DEADLINE_S = 2.0
"""The world's tick deadline (``--deadline``) for a swarm of up to 200 agents."""
DEADLINE_PER_AGENT_S = 0.01
"""The deadline for each agent of a larger swarm: on 2 cores a tick of 512 agents takes about a
second, and with the 2 s of small swarms some of their intents come too late at every episode
(docs/performance.md, "How many agents a machine holds")."""


def option(default, help: str, flag: str | tuple[str, ...] | None = None, **argparse_options):
    """A config field with its command-line option: ``flag`` (default ``--<name>``; a tuple for
    several names), ``help``, and any other ``argparse`` keyword (``choices``, ``metavar``)."""
    return field(default=default, metadata={"help": help, "flag": flag, **argparse_options})


LEARNING_FIELDS = ("algo", "alpha", "beta", "interaction_radius", "wait_rule", "optimistic",
                   "known_state", "shared", "shield", "lookahead", "still_terminal",
                   "stay_reward", "ds_state", "ds_reward", "detour", "still_shield",
                   "escape_shield", "arbitration", "map_known")
"""The fields a learning preset sets; everything else (agents, grid, seed, episodes...) is the
run's."""

PAPER: dict[str, Any] = {"algo": "nnql", "alpha": 0.9, "beta": 0.5, "interaction_radius": VIEW_RADIUS,
         "wait_rule": "reach", "optimistic": 0.0, "known_state": False, "shared": False,
         "shield": False, "lookahead": 1, "still_terminal": False, "stay_reward": 0.5,
         "ds_state": "goal", "ds_reward": "euclid", "detour": False, "still_shield": False,
         "escape_shield": False, "arbitration": "paper", "map_known": False}
"""The paper's reading: every neighbour in view enters Eq. 6 and is waited for if it outranks
the agent, zero-initialised tables, each agent its own tables, no shield."""

BEST: dict[str, Any] = {"interaction_radius": 2, "optimistic": 25.0, "shared": True, "still_terminal": True,
        "alpha": 0.5}
"""The learning options beyond the paper that the swarm experiment found best (docs/swarm.md):
neighbours within collision reach only, optimistic tables, one table for the swarm, no future
learned from a step that went nowhere, a gentler learning rate."""

PATH = {"ds_state": "progress", "ds_reward": "flat", "detour": True, "beta": 0.9}
"""Destination seeking on the walls an agent has seen (docs/swarm.md, "Walls"): its state the
moves that bring it nearer on its known map, a flat reward for getting nearer, the path around
the agents parked within reach, and destination seeking weighed 0.9 in Eq. 7 (its flat rewards
are small beside collision avoidance's)."""

PRESETS: dict[str, dict] = {
    "ql": {**PAPER, "algo": "ql"},
    "nnql": PAPER,
    "best-ql": {**PAPER, **BEST, "algo": "ql"},
    "best-nnql": {**PAPER, **BEST, "algo": "nnql-dir"},
    "shield-ql": {**PAPER, **BEST, "algo": "ql", "shield": True, "known_state": True},
    "shield-nnql": {**PAPER, **BEST, "algo": "nnql", "shield": True, "known_state": True,
                    "wait_rule": "meet"},
    "path-nnql": {**PAPER, **BEST, "algo": "nnql", "shield": True, "known_state": True,
                  "wait_rule": "meet", **PATH, "escape_shield": True},
    "pibt-nnql": {**PAPER, **BEST, "algo": "nnql", "known_state": True, "wait_rule": "meet",
                  **PATH, "arbitration": "pibt"},
    "nnql-n2": {**PAPER, **BEST, "algo": "nnql", "lookahead": 2, "interaction_radius": 4},
    "daql": {**PAPER, **BEST, "algo": "daql"},
    "oracle": {**PAPER, "algo": "oracle"},
}
"""Named learning presets: the rows of the swarm experiment, and ``launch/swarm.py --preset``."""
assert all(set(preset) == set(LEARNING_FIELDS) for preset in PRESETS.values())

DEFAULT_PRESET = "path-nnql"
"""The learning options of a swarm run unless told otherwise: the best of the swarm experiment
(docs/swarm.md: the paper's nnQL with the shield and its escape rule, destination seeking on the
walls each agent has seen)."""
_DEFAULT = PRESETS[DEFAULT_PRESET]


REQUIRED_KEYS = ("run_id", "n_agents", "episodes", "max_steps", "width", "height", "seed")
"""What every ``config.json`` a run wrote holds (later fields are defaulted when missing)."""


@dataclass(frozen=True)
class SwarmConfig:
    """Every knob of a swarm run. The learning options default to :data:`DEFAULT_PRESET`; the
    rest are the swarm's world (8 agents on the paper's 11 x 11 grid, swaps counted)."""

    run_id: str = "run"
    n_agents: int = option(8, "number of agents", "--agents")
    episodes: int = option(100, "episodes of the run")
    max_steps: int = option(100, "steps per episode at most")
    width: int = 11
    height: int = 11
    seed: int = option(0, "the run's seed: every random draw comes from it")
    algo: str = option(_DEFAULT["algo"], "how agents learn: the paper's nnQL and QL, nnQL with the "
                       "announced move in the state, Double Action Q-learning, or the oracle, "
                       "a reference planner (PIBT; not a lower bound; in-process only)",
                       choices=ALGOS)
    random_step: int = option(20, "every k-th action is random (the paper's random step)",
                              metavar="K")
    alpha: float = option(_DEFAULT["alpha"], "learning rate")
    gamma: float = option(0.6, "discount factor")
    beta: float = option(_DEFAULT["beta"], "weight of destination seeking in Q_final (Eq. 7)")
    goal_reward: float = option(10.0, "destination-seeking reward on arriving")
    stay_reward: float = option(_DEFAULT["stay_reward"], "destination-seeking reward times d for a step that kept "
                                "the distance, i.e. did not move (the paper's 0.5)")
    count_swaps: bool = option(True, "count two agents swapping cells as a collision")
    interaction_radius: int = option(_DEFAULT["interaction_radius"], "neighbours within this many cells (Chebyshev) "
                                     "enter Eq. 6, learn (Eq. 10) and are waited for; the "
                                     "paper's reading is the whole view, 10 (which makes the "
                                     "negotiation one chain when everyone sees everyone)",
                                     ("--radius", "--negotiation-radius"))
    wait_rule: str = option(_DEFAULT["wait_rule"], "whom an agent waits for before it decides: "
                            "every higher-ranked neighbour within the radius (reach, the "
                            "paper's), or only those it could meet on the next step (meet)",
                            choices=WAIT_RULES)
    optimistic: float = option(_DEFAULT["optimistic"], "initial value of every Q-table entry (the paper: 0)")
    known_state: bool = option(_DEFAULT["known_state"], "a state block of its own for a neighbour whose next cell "
                               "is known (announced, or arrived on its goal)")
    shared: bool = option(_DEFAULT["shared"], "the agents learn into one table, each agent's updates of a "
                          "tick applied by all in agent-id order before the next")
    shield: bool = option(_DEFAULT["shield"], "never move into a cell a known neighbour announced, into a "
                          "swap, or into an arrived agent")
    still_shield: bool = option(_DEFAULT["still_shield"], "the shield (--shield) also forbids "
                                "the cell of a neighbour whose intent is unknown and that did "
                                "not move last step (taken as staying)")
    escape_shield: bool = option(_DEFAULT["escape_shield"], "the shield (--shield) also forbids "
                                 "the cell of a neighbour whose intent is unknown unless a cell "
                                 "next to it is surely free to move on to: empty, announced by "
                                 "nobody, next to no other agent of unknown intent (priority "
                                 "inheritance, one level deep)")
    lookahead: int = option(_DEFAULT["lookahead"], "n of nnQL: the neighbour's state is its announced cell n "
                            "steps ahead (in-process only for n > 1)", metavar="N")
    still_terminal: bool = option(_DEFAULT["still_terminal"], "a step that went nowhere ends its destination-seeking "
                                  "return (no bootstrap from the state it stayed in)")
    ds_state: str = option(_DEFAULT["ds_state"], "destination seeking's state: the goal's "
                           "offset (the paper's), the next cell of a shortest path on the walls "
                           "the agent has seen (waypoint), or the moves that bring it nearer "
                           "on that map (progress)", choices=DS_STATE_NAMES)
    ds_reward: str = option(_DEFAULT["ds_reward"], "destination seeking's reward: 1/d, 0.5/d, 0 "
                            "with d the Euclidean distance to the goal (euclid, the paper's), "
                            "the same with d the path length on the walls the agent has seen "
                            "(path), or 1, 0.5, 0 for a path that got shorter, stayed, grew "
                            "(flat)", choices=DS_REWARD_NAMES)
    detour: bool = option(_DEFAULT["detour"], "the path on the known map (--ds-state, "
                          "--ds-reward) goes around the arrived agents within reach, where "
                          "another way is known")
    on_target: str = option("", "what an agent that reached its goal does: stays there for "
                            "good, an obstacle (park, the paper's reading), or stays unless it "
                            "has to make way, and may leave and come back, counted arrived "
                            "only while there, its last arrival its arrival (step-aside, the "
                            "field's); by default step-aside under --arbitration pibt or --tasks "
                            "lifelong, else park",
                            choices=ON_TARGET)
    map_known: bool = option(_DEFAULT["map_known"], "every agent knows every wall of the map "
                             "from the start (as the field's planners, and its learned methods' "
                             "shortest-path inputs, do); else it learns the walls it sees "
                             "(within 10 cells) and keeps them for the run")
    tasks: str = option("one-shot", "what an agent that reached its goal does next: nothing "
                        "more this episode (one-shot), or it is given a new goal at once, drawn "
                        "from the free cells it can reach, and the episode runs --max-steps "
                        "steps, scored by goals reached a step (lifelong, the field's "
                        "throughput)", choices=TASKS)
    arbitration: str = option(_DEFAULT["arbitration"], "how the world settles a tick's moves: "
                              "every agent's intent applied at once, colliding moves blocked "
                              "and counted (paper), or priority inheritance over each agent's "
                              "announced order of its moves (pibt: nobody collides; a refused "
                              "first choice earns no collision-avoidance reward; needs "
                              "--on-target step-aside)", choices=ARBITRATIONS)
    obstacle_density: float = option(0.0, "fraction of the grid's cells that are walls (static "
                                     "obstacles drawn from the seed; starts and goals in the "
                                     "largest free region)", metavar="P")
    tick_deadline_s: float = option(0.0, "seconds the world waits for intents each tick "
                                    f"(default: {DEADLINE_S:g}, or {DEADLINE_PER_AGENT_S * 1000:g} "
                                    "ms an agent where that is longer: a tick takes longer "
                                    "with more agents)", "--deadline")
    map_name: str = ""
    """Where the map came from (``--map``: a file or a generator's spec); "" without a map."""
    map_rows: tuple[str, ...] = ()
    """The run's map (``world.terrain``), one string per row, ``.`` free and ``@`` wall; empty:
    the open grid, or walls drawn at ``obstacle_density``."""
    scenario: tuple[tuple[int, int, int, int], ...] = ()
    """Every episode's ``(start_x, start_y, goal_x, goal_y)`` per agent (``--scen``); empty:
    drawn per episode from the seed."""
    goal_lists: tuple[tuple[int, ...], ...] = ()
    """A lifelong run's given goals after each agent's first (``--goals``: ``x, y`` pairs in
    order, flat, per agent; ``world.tasks``); empty: all drawn."""
    frozen: bool = False
    """Play learned tables as they are: no learning, no random step (the simulator only; the
    maps benchmark, ``experiment.maps_benchmark``, loads the tables: ``sim.runs.Batch.load_tables``)."""

    def __post_init__(self) -> None:
        validate_run_id(self.run_id)
        # JSON gives lists: the config is frozen and hashable, so they become tuples
        object.__setattr__(self, "map_rows", tuple(self.map_rows))
        if not self.tick_deadline_s:  # the deadline of the swarm's size
            object.__setattr__(self, "tick_deadline_s",
                               max(DEADLINE_S, DEADLINE_PER_AGENT_S * self.n_agents))
        if not self.on_target:  # the on-target rule of the arbitration
            object.__setattr__(self, "on_target",
                               "step-aside" if self.arbitration == "pibt" or self.lifelong
                               else "park")
        object.__setattr__(self, "scenario", tuple(tuple(int(v) for v in task)
                                                   for task in self.scenario))
        object.__setattr__(self, "goal_lists", tuple(tuple(int(v) for v in goals)
                                                     for goals in self.goal_lists))
        checks = [
            (1 <= self.n_agents <= MAX_AGENTS, f"agents must be 1..{MAX_AGENTS}"),
            (self.episodes >= 1, "episodes must be at least 1"),
            (self.max_steps >= 1, "max steps must be at least 1"),
            (self.episodes * self.episode_ticks < MAX_TICK,
             f"episodes x (max steps + 1) ticks must stay below {MAX_TICK}, the messages' "
             f"largest tick"),
            (2 <= self.width <= MAX_GRID and 2 <= self.height <= MAX_GRID,
             f"the grid must be 2..{MAX_GRID} cells per side"),
            (2 * self.n_agents <= self.width * self.height,
             f"{self.n_agents} agents need {2 * self.n_agents} distinct start and goal cells, "
             f"a {self.width}x{self.height} grid has {self.width * self.height}"),
            (self.seed >= 0, "the seed must be non-negative"),
            (self.algo in ALGOS, f"algo must be one of {', '.join(ALGOS)}"),
            (self.random_step >= 1, "the random step k must be at least 1"),
            (0 < self.alpha <= 1 and 0 <= self.gamma < 1 and 0 <= self.beta <= 1,
             "alpha must be in (0, 1], gamma in [0, 1), beta in [0, 1]"),
            (0 <= self.interaction_radius <= VIEW_RADIUS,
             f"the interaction radius must be 0..{VIEW_RADIUS}"),
            (self.wait_rule in WAIT_RULES, f"the wait rule must be one of {', '.join(WAIT_RULES)}"),
            (0 <= self.optimistic <= MAX_REWARD,
             f"the optimistic initial value must be 0..{MAX_REWARD:g} (a Q-value the messages "
             f"carry)"),
            (0 <= self.stay_reward <= MAX_REWARD,
             f"the stay reward must be 0..{MAX_REWARD:g} (a reward the messages carry)"),
            (-MAX_REWARD <= self.goal_reward <= MAX_REWARD,
             f"the goal reward must be -{MAX_REWARD:g}..{MAX_REWARD:g} (a reward the messages "
             f"carry)"),
            (1 <= self.lookahead <= MAX_LOOKAHEAD, f"the lookahead n must be 1..{MAX_LOOKAHEAD}"),
            (self.lookahead == 1 or self.algo in ("nnql",), "a lookahead n > 1 needs --algo nnql"),
            (self.ds_state in DS_STATE_NAMES,
             f"the destination-seeking state must be one of {', '.join(DS_STATE_NAMES)}"),
            (self.ds_reward in DS_REWARD_NAMES,
             f"the destination-seeking reward must be one of {', '.join(DS_REWARD_NAMES)}"),
            (self.lookahead == 1 or self.ds_state == "goal",
             "a lookahead n > 1 plans on the goal's offset: it needs --ds-state goal"),
            (self.on_target in ON_TARGET,
             f"the on-target rule must be one of {', '.join(ON_TARGET)}"),
            (self.tasks in TASKS, f"the tasks must be one of {', '.join(TASKS)}"),
            (self.tasks != "lifelong" or self.max_steps <= MAX_LIFELONG_STEPS,
             f"a lifelong episode is at most {MAX_LIFELONG_STEPS} steps"),
            (self.tasks != "lifelong" or self.on_target == "step-aside",
             "in a lifelong run nobody stays on a goal: it needs --on-target step-aside"),
            (self.tasks != "lifelong" or self.lookahead == 1,
             "a lifelong run plays a lookahead n of 1"),
            (self.arbitration in ARBITRATIONS,
             f"the arbitration must be one of {', '.join(ARBITRATIONS)}"),
            (self.arbitration != "pibt" or self.on_target == "step-aside",
             "priority inheritance (--arbitration pibt) moves agents off their goals: it needs "
             "--on-target step-aside"),
            (self.arbitration != "pibt" or self.ds_state != "goal",
             "--arbitration pibt orders an agent's moves on the map it knows: it needs "
             "--ds-state waypoint or progress"),
            (self.arbitration != "pibt" or not self.shield,
             "under --arbitration pibt nobody collides: the shield (--shield) has nothing to do"),
            (self.arbitration != "pibt" or self.algo in NEGOTIATING_ALGOS,
             "--arbitration pibt needs a learner that negotiates (nnql, nnql-dir)"),
            (0 < self.tick_deadline_s < math.inf, "the tick deadline must be positive and finite"),
            (0 <= self.obstacle_density <= MAX_DENSITY,
             f"the obstacle density must be 0..{MAX_DENSITY}"),
            (self.map_rows or not self.scenario, "a scenario (--scen) needs its map (--map)"),
            (not self.goal_lists or (self.lifelong and self.scenario),
             "given goals (--goals) are a lifelong run's (--tasks lifelong), with its starts"),
            (not self.map_rows or self.obstacle_density == 0,
             "a map brings its own walls: give --map or --obstacle-density, not both"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)
        if self.q_bound() > MAX_REWARD:
            raise ValueError(
                f"Q-values may reach {self.q_bound():.3g} (the largest of the optimistic value "
                f"and the largest reward / (1 - gamma)), above {MAX_REWARD:g}, the largest the "
                f"messages carry: lower the rewards, --optimistic or --gamma")
        if self.map_rows:
            self._check_map()
        free = len(self.open_cells())
        if (self.obstacle_density or self.map_rows) and not self.scenario \
                and 2 * self.n_agents > free:
            where = (f"the map {self.map_name or ''}".rstrip() if self.map_rows else
                     f"a {self.width}x{self.height} grid at obstacle density "
                     f"{self.obstacle_density}")
            raise ValueError(
                f"{self.n_agents} agents need {2 * self.n_agents} distinct start and goal cells; "
                f"the largest free region of {where} has {free}")
        # Digested now, so that it goes with the config to every process of the run: an agent
        # that digested it itself would load OpenSSL's digests, 1.4 MiB of its memory.
        self.identity

    def _check_map(self) -> None:
        """The map fits the grid; the scenario, if any, has a task per agent on distinct free
        cells."""
        rows = self.map_rows
        if len(rows) != self.height or any(len(row) != self.width for row in rows):
            raise ValueError(f"the map's rows must be {self.height} of {self.width} cells, "
                             f"the grid's size")
        if any(set(row) - {".", "@"} for row in rows):
            raise ValueError("the map's rows hold only '.' (free) and '@' (wall)")
        if self.scenario:
            if len(self.scenario) != self.n_agents:
                raise ValueError(f"the scenario has {len(self.scenario)} tasks for "
                                 f"{self.n_agents} agents")
            starts = [(sx, sy) for sx, sy, _, _ in self.scenario]
            goals = [(gx, gy) for _, _, gx, gy in self.scenario]
            distinct_goals = self.lifelong or len(set(goals)) == len(goals)
            if len(set(starts)) != len(starts) or not distinct_goals or not all(
                    0 <= x < self.width and 0 <= y < self.height and rows[y][x] == "."
                    for x, y in starts + goals):
                raise ValueError("the scenario's starts, and its goals, must be distinct free "
                                 "cells of the map")
        if self.goal_lists:
            if len(self.goal_lists) != self.n_agents:
                raise ValueError(f"the given goals are {len(self.goal_lists)} agents' for "
                                 f"{self.n_agents} agents")
            if not all(len(goals) % 2 == 0 and all(
                    0 <= x < self.width and 0 <= y < self.height and rows[y][x] == "."
                    for x, y in zip(goals[::2], goals[1::2])) for goals in self.goal_lists):
                raise ValueError("the given goals must be free cells of the map, x y each")

    def q_bound(self) -> float:
        """What no Q-value of the run exceeds in magnitude: the initial value, or a return
        of the largest set reward for ever (a Q-learning update keeps every value within
        ``max(|Q|, |r| / (1 - gamma))``). The world's fixed rewards (1/d, and collision avoidance's
        10, ``world.rules``) are not counted: below ``MAX_REWARD`` for a gamma up to 0.99999."""
        largest = max(abs(self.goal_reward), self.stay_reward)
        return max(self.optimistic, largest / (1 - self.gamma))

    @cached_property  # the world reads it every tick: worked out once (the config is frozen)
    def n_walls(self) -> int:
        """How many walls the grid holds (``protocol.walls``)."""
        if self.map_rows:
            return sum(row.count("@") for row in self.map_rows)
        return wall_count(self.width, self.height, self.obstacle_density)

    @property
    def episode_ticks(self) -> int:
        """The most ticks an episode takes (``world.engine``): its ``max_steps`` moves, then its
        end tick. A run's ticks count from 0, so episode ``e`` begins at tick
        ``e * episode_ticks`` at the latest (earlier where episodes end sooner, or where a
        resumed world starts its clock afresh)."""
        return self.max_steps + 1

    @property
    def lifelong(self) -> bool:
        """Whether an agent is given a new goal on reaching its goal (``world.tasks``)."""
        return self.tasks == "lifelong"

    @property
    def step_aside(self) -> bool:
        """Whether an arrived agent may leave its goal to make way (``world.rules``); if not, it
        is *parked* (``park``): it stays on its goal for the rest of the episode, so every
        observation that shows it says so and its intent, STAY, is known without asking."""
        return self.on_target == "step-aside"

    @property
    def meet_only(self) -> bool:
        """Whether agents wait only for the neighbours they could meet next step (the ``meet``
        wait rule, ``protocol.ranks``)."""
        return self.wait_rule == "meet"

    @property
    def quiet_settled(self) -> bool:
        """Whether an arrived agent takes no part in the ticks that follow, until the episode's
        end tick (``world.engine``: it is *settled*, the world waits for no intent from it, and
        *quiet*, the world sends it no observation): under ``meet``, where nobody waits for an
        arrived agent and it waits for nobody (when arrived agents park), and where the agents do
        not negotiate (an arrived one never learns an intent that would make it move). Under
        ``reach`` an arrived nnQL agent still relays the intents it learns down the chain, in
        lockstep; under ``step-aside`` it may have to make way."""
        return not self.lifelong and ((self.meet_only and not self.step_aside)
                                      or self.algo not in NEGOTIATING_ALGOS)

    @cached_property
    def n_bodies(self) -> int:
        """Agents, then walls: body ``n_agents + k`` is wall ``k``."""
        return self.n_agents + self.n_walls

    def walls(self) -> np.ndarray:
        """The run's walls, ``(K, 2)`` cells in cell order (read-only)."""
        return layout(self.seed, self.width, self.height, self.obstacle_density, self.map_rows)[0]

    def open_cells(self) -> np.ndarray:
        """The cells starts and goals are drawn from (``y * W + x``; read-only)."""
        return layout(self.seed, self.width, self.height, self.obstacle_density, self.map_rows)[1]

    def learning(self) -> dict:
        """The options of :data:`LEARNING_FIELDS`, as a preset would give them."""
        return {name: getattr(self, name) for name in LEARNING_FIELDS}

    @cached_property
    def identity(self) -> str:
        """The run's identity: a digest of the options that make it (:data:`IDENTITY_FIELDS`,
        the run id and seed among them), in ``config.json`` and in every checkpoint, so that a
        resumed run takes no file of another run, however alike in shape."""
        values = {name: getattr(self, name) for name in IDENTITY_FIELDS}
        values.update({name: getattr(self, name) for name, default in LATER_FIELDS.items()
                       if getattr(self, name) != default})
        text = json.dumps(values, sort_keys=True, default=list)
        return hashlib.sha256(text.encode()).hexdigest()[:16]

    def to_json(self) -> str:
        return json.dumps({**asdict(self), "identity": self.identity}, indent=2, sort_keys=True)

    @staticmethod
    def from_json(text: str) -> "SwarmConfig":
        """The config of :meth:`to_json`'s text; raises ValueError (or TypeError, for a value of
        the wrong type) for anything else: not an object, or one without a run's own keys."""
        data = json.loads(text)
        if not isinstance(data, dict):
            kind = {list: "an array", str: "a string", type(None): "null", bool: "a boolean"}
            raise ValueError(f"a config is a JSON object, not {kind.get(type(data), 'a number')}")
        missing = [name for name in REQUIRED_KEYS if name not in data]
        if missing:
            raise ValueError(f"no {', '.join(missing)}: not a run's config")
        identity = data.pop("identity", None)  # written since runs carry their identity
        data.setdefault("wait_rule", "reach")  # a config without the field: all in reach waited for
        data.setdefault("ds_state", "goal")  # a config without these fields: the paper's
        data.setdefault("ds_reward", "euclid")
        data.setdefault("detour", False)
        data.setdefault("still_shield", False)
        data.setdefault("escape_shield", False)
        data.setdefault("arbitration", "paper")
        data.setdefault("tasks", "one-shot")
        data.setdefault("map_known", False)
        known = {f.name for f in fields(SwarmConfig)}
        unknown = set(data) - known
        if unknown:
            raise ValueError(f"unknown config keys: {', '.join(sorted(unknown))}")
        config = SwarmConfig(**data)
        if identity is not None and identity != config.identity:
            raise ValueError(f"its options are not the run's it names (identity {identity!r}, "
                             f"the options' {config.identity!r}): edited after the run began")
        return config


IDENTITY_FIELDS = (
    "run_id", "n_agents", "episodes", "max_steps", "width", "height", "seed", "algo",
    "random_step", "alpha", "gamma", "beta", "goal_reward", "stay_reward", "count_swaps",
    "interaction_radius", "wait_rule", "optimistic", "known_state", "shared", "shield",
    "still_shield", "escape_shield", "lookahead", "still_terminal", "ds_state", "ds_reward",
    "detour", "on_target", "obstacle_density", "tick_deadline_s", "map_name", "map_rows",
    "scenario", "frozen",
)
"""The fields the run's identity digests (:attr:`SwarmConfig.identity`): every field there was
when runs began to carry it, named here so that a field added later leaves the runs made before
it their identity (add one only with a default that leaves those runs' digests alone)."""
LATER_FIELDS: dict[str, Any] = {"arbitration": "paper", "tasks": "one-shot", "map_known": False,
                                "goal_lists": ()}
"""Fields added since runs began to carry their identity, with the value every run made before
them has: the identity digests one only where a run's value differs from it."""
assert set(IDENTITY_FIELDS) | set(LATER_FIELDS) <= {f.name for f in fields(SwarmConfig)}
