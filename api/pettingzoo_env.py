"""A PettingZoo ``ParallelEnv`` over the world rules: N learning agents, each seeking its own goal.

## Configuration
The swarm's own config (:class:`~nnql_swarm.protocol.config.SwarmConfig`):
``SwarmGridEnv(swarm.config)`` plays the world of ``Swarm(...)``'s run, or options by name, as
``Swarm`` takes them (``SwarmGridEnv(n_agents=4, width=8, height=8, negotiation_radius=2)``,
``SwarmGridEnv(map="maps/....map", tasks="lifelong")``), over the paper's reading (the ``nnql``
preset: every agent in view waited for) where they say nothing. The world is the swarm's own
(:class:`world.engine.SwarmWorld`): the grid or the map and its walls, a scenario, ``max_steps``,
``count_swaps``, the rewards, the on-target rule, the arbitration (under ``pibt`` each agent's
action is its whole order: it is never pushed) and the task mode are the run's.

## Description
A swarm episode (:func:`world.scenario.swarm_episode`): ``n_agents`` agents start on distinct
free cells, each with its own goal cell, all starts and goals distinct. Every step all agents
move at once and the world resolves the moves (``world.rules``): two agents trying to occupy one
cell collide and stay where they were, and so do two agents swapping cells when ``count_swaps``
is set (the default, as in swarm mode); a wall is never entered. ``reset(options={"starts":
[(x, y), ...], "goals": [(x, y), ...]})`` plays those starts and goals instead (a scenario).

## Action space
``Discrete(5)`` per agent, the paper's actions (:mod:`protocol.actions`):

- 0: UP (y - 1)
- 1: DOWN (y + 1)
- 2: LEFT (x - 1)
- 3: RIGHT (x + 1)
- 4: STAY

A move off the grid leaves the agent where it is, without a collision.

## Observation space
``MultiDiscrete`` of length ``n_agents``, the egocentric states of the paper (one of 441 relative
offsets ``(dx, dy)`` in ``[-10, 10]^2``, :func:`protocol.actions.offset_state`):

- ``obs[0]``: the goal's offset from the agent (clipped to the window's edge on large grids);
- ``obs[1:]``: one slot per other agent, in agent-id order: that agent's offset from this one, or
  ``441`` (``NOT_IN_VIEW``) when it is more than 10 cells away along an axis.

This is the QL reading of the neighbour state: a parallel step has no moment at which neighbours
could announce their next actions, so nnQL's negotiation lives in the swarm runtime, not here.
Agents that have arrived stay on their goals and are still seen (and can still be run into).

## Rewards
Per step, the paper's two rewards added (:mod:`world.rules`): destination seeking ``1/d`` if the
Euclidean distance ``d`` to the goal decreased, ``0.5/d`` if it stayed, 0 if it grew, and
``goal_reward`` on arriving (``0.5/d`` is ``stay_reward / d``); plus collision avoidance ``CA_REWARD`` (10) without a collision, 0 with
one. ``infos[agent]`` holds the two parts (``reward_ds``, ``reward_ca``) and ``collided``.

## Negotiation
``infos[agent]["waits_for"]`` names the agents whose intents this agent would wait for before
its next step in the swarm's negotiation (``protocol.ranks.waits_for``: higher-ranked agents within
``interaction_radius``, all of them or, with ``wait_rule="meet"``, those on their way that it could
meet on the next step; ranks rotating every step), so that a policy that reads intents can be
stepped in that order.

## Episode end
One goal each (``tasks="one-shot"``): an agent is terminated when it reaches its goal, and then
leaves ``agents``, parked on it (``on_target="park"``); under ``on_target="step-aside"`` an agent
on its goal stays among ``agents`` (it may have to make way) and all are terminated together
when every one is home. Lifelong (``tasks="lifelong"``): an agent that reaches its goal is given
the next at once (``infos[agent]["reached"]``, its observation's goal the new one), and nobody is
terminated. Every agent still among ``agents`` is truncated after ``max_steps`` steps.

## Rendering
``render_mode`` (PettingZoo's convention: chosen at construction, ``render()`` takes no argument):

- ``"human"``: each ``render()`` logs the grid, the goals and the agents to Rerun on the timelines
  ``step`` (every ``render()`` call) and ``episode``, and returns None. Where the frames go is the
  ``rerun`` argument: a path (``.rrd``) saves them there (open it with ``nnql-view``), a viewer URL
  (``rerun+http://host:9876/proxy``) streams them to that viewer, and None (the default) spawns
  the native viewer where there is a display (``DISPLAY`` or ``WAYLAND_DISPLAY`` on Linux) and
  otherwise keeps them in memory (``env.rerun_memory``, a ``rerun.MemoryRecording``) with a
  warning that says how to see them, so that a machine without a screen never fails.
- ``"rgb_array"``: an ``(height * cell_pixels, width * cell_pixels, 3)`` ``uint8`` picture:
  grid lines, walls dark grey, each goal a square outline and each agent a disc in the agent's colour (the
  colours of the swarm's recording, ``recording.world.agent_colors``).
- ``"ansi"``: a string, one line per row: ``.`` a free cell, ``#`` a wall, ``a``, ``b``, ...
  goals, ``A``, ``B``, ... agents.

## Seeding
``reset(seed=S)`` starts episode 0 of seed ``S``; each later ``reset()`` without a seed moves on to the
next episode of the same seed. Scenarios come from :mod:`protocol.seeding` streams, and the
dynamics draw nothing, so the same seed and actions give the same trajectory.
"""

import dataclasses
import functools
import os
import sys
import warnings
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from nnql_swarm.api.options import config_of
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, STAY, offset_state, sees
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.ranks import awaits_answer
from nnql_swarm.world.engine import SwarmWorld

NOT_IN_VIEW = N_STATES
"""The observation slot value of another agent out of view."""

ENV_PRESET = "nnql"
"""The learning options the env's config takes where its options say nothing: the paper's
reading (every agent in view waited for)."""


def env_config(config: SwarmConfig | None, options: dict) -> SwarmConfig:
    """The env's config: ``config``, or one of ``options`` by name (``api.options.config_of``)
    over :data:`ENV_PRESET`; raises ValueError for a bad option."""
    if config is None:
        return config_of({"preset": ENV_PRESET, **options}, run_id="env")
    if options:
        raise ValueError("give a SwarmConfig or options, not both")
    return config


class SwarmGridEnv(ParallelEnv):
    """N agents on a grid, each reaching for its own goal while avoiding the others."""

    metadata: dict[str, Any] = {"name": "nnql_swarm_grid_v0", "render_modes": ["human", "rgb_array", "ansi"],
                "is_parallelizable": True, "render_fps": 4}

    def __init__(
        self,
        config: SwarmConfig | None = None,
        *,
        render_mode: str | None = None,
        rerun: str | Path | None = None,
        cell_pixels: int = 16,
        **options,
    ) -> None:
        """``config``: the swarm's (``Swarm(...).config``), or ``options`` by name as ``Swarm``
        takes them (module docstring)."""
        config = env_config(config, options)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unsupported render mode {render_mode!r}")
        self.config = config
        n_agents = self.n_agents = config.n_agents
        self.width, self.height = config.width, config.height
        self.max_steps = config.max_steps
        self.count_swaps = config.count_swaps
        self.negotiation_radius = config.interaction_radius
        self.meet_only = config.meet_only
        if cell_pixels < 4:
            raise ValueError(f"cell_pixels must be at least 4, got {cell_pixels}")
        self.render_mode = render_mode
        self.rerun_target = rerun
        self.cell_pixels = cell_pixels
        self.rerun_memory = None  # the frames of "human" where no viewer was there to take them
        self._stream = None
        self._frame = 0
        self.possible_agents = [f"agent_{i}" for i in range(n_agents)]
        self.agents: list[str] = []
        self._index = {name: i for i, name in enumerate(self.possible_agents)}
        self._seed: int | None = None
        self._episode = -1
        self._x, self._y = [0] * n_agents, [0] * n_agents
        self._goal_x, self._goal_y = [0] * n_agents, [0] * n_agents
        self._arrived = [False] * n_agents
        self._world: SwarmWorld | None = None
        self._told: list = []
        self._walls: list = []

    @functools.lru_cache(maxsize=None)
    def observation_space(self, agent: str) -> spaces.MultiDiscrete:
        return spaces.MultiDiscrete([N_STATES] + [N_STATES + 1] * (self.n_agents - 1), dtype=np.int64)

    @functools.lru_cache(maxsize=None)
    def action_space(self, agent: str) -> spaces.Discrete:
        return spaces.Discrete(N_ACTIONS)

    def reset(self, seed: int | None = None, options: dict | None = None):
        if seed is not None:
            self._seed, self._episode = int(seed), 0
        else:
            if self._seed is None:
                entropy = np.random.SeedSequence().entropy
                assert isinstance(entropy, int), "a SeedSequence made without entropy draws it"
                self._seed = int(entropy % 2**63)
            self._episode += 1
        config = dataclasses.replace(self.config, seed=self._seed,
                                     episodes=max(self.config.episodes, self._episode + 1),
                                     **self._placed(options or {}))
        self._world = SwarmWorld(config, first_episode=self._episode)
        self._walls = config.walls().tolist()
        self._read()
        self.agents = list(self.possible_agents)
        observations = {agent: self._observe(self._index[agent]) for agent in self.agents}
        return observations, {agent: {} for agent in self.agents}

    def _placed(self, options: dict) -> dict:
        """The config's fields for ``reset``'s ``options``: ``starts`` and ``goals`` given, a
        scenario (on the config's map, or the open grid)."""
        given = {"starts", "goals"} & set(options)  # others are not the env's: ignored
        if not given:
            return {}
        if len(given) == 1:
            raise ValueError("reset options give both starts and goals, or neither")
        c = self.config
        rows = c.map_rows or ("." * c.width,) * c.height
        tasks = tuple((int(sx), int(sy), int(gx), int(gy))
                      for (sx, sy), (gx, gy) in zip(options["starts"], options["goals"]))
        return {"map_rows": rows, "scenario": tasks}

    def _read(self) -> None:
        """The world's state as the observations give it."""
        assert self._world is not None, "read after reset"
        told = self._world.observations()
        self._x = [o.position[0] for o in told]
        self._y = [o.position[1] for o in told]
        self._goal_x = [o.goal[0] for o in told]
        self._goal_y = [o.goal[1] for o in told]
        self._arrived = [o.arrived for o in told]
        self._told = told

    def step(self, actions: dict):
        live = list(self.agents)
        chosen: list[int | None] = [STAY] * self.n_agents  # agents that left stay
        for agent in live:
            chosen[self._index[agent]] = int(actions.get(agent, STAY))
        if self._world is None:
            raise RuntimeError("reset() the env before its first step")
        self._world.apply(chosen)
        self._read()
        c, told = self.config, self._told
        truncated = self._world.step >= self.max_steps
        everyone_home = all(self._arrived)
        observations, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        for agent in live:
            i = self._index[agent]
            seen = told[i]
            observations[agent] = self._observe(i)
            rewards[agent] = seen.reward_ds + seen.reward_ca
            if c.lifelong:
                done = False
            elif c.step_aside:
                done = everyone_home
            else:
                done = seen.arrived
            terminations[agent] = done
            truncations[agent] = truncated and not done
            infos[agent] = {"reward_ds": seen.reward_ds, "reward_ca": seen.reward_ca,
                            "collided": seen.collided, "waits_for": self._waits_for(i)}
            if c.lifelong:
                infos[agent]["reached"] = seen.arrived
        self.agents = [a for a in live if not (terminations[a] or truncations[a])]
        return observations, rewards, terminations, truncations, infos

    def _waits_for(self, i: int) -> list[str]:
        """The agents whose intents agent ``i`` waits for before the next step (the ranks its
        world gives this tick)."""
        told, x, y = self._told, self._x, self._y
        return [self.possible_agents[j] for j in range(self.n_agents)
                if j != i and awaits_answer(told[i].rank, told[j].rank, x[i], y[i], x[j], y[j],
                                            self.negotiation_radius, self.meet_only,
                                            self._arrived[i], self._arrived[j])]

    def render(self) -> "str | np.ndarray | None":
        """The current state in the ``render_mode`` (module docstring); None without one."""
        if self.render_mode == "ansi":
            return self._text()
        if self.render_mode == "rgb_array":
            return self._picture()
        if self.render_mode == "human":
            self._log_frame()
        return None

    def close(self) -> None:
        """Flush and close the Rerun stream of ``"human"`` (a spawned viewer stays open); frames
        kept in memory stay readable in ``rerun_memory``."""
        if self._stream is None:
            return
        if self.rerun_memory is not None:
            self._stream.flush()  # disconnecting would drop the memory sink's frames
            return
        from nnql_swarm.recording.sinks import close_stream

        close_stream(self._stream)
        self._stream = None

    def _text(self) -> str:
        rows = [["." for _ in range(self.width)] for _ in range(self.height)]
        for x, y in self._walls:
            rows[y][x] = "#"
        for i, (x, y) in enumerate(zip(self._goal_x, self._goal_y)):
            rows[y][x] = chr(ord("a") + i % 26)
        for i, (x, y) in enumerate(zip(self._x, self._y)):
            rows[y][x] = chr(ord("A") + i % 26)
        return "\n".join("".join(row) for row in rows)

    def _picture(self) -> np.ndarray:
        from nnql_swarm.recording.palette import agent_colors

        c = self.cell_pixels
        image = np.full((self.height * c, self.width * c, 3), 255, dtype=np.uint8)
        image[::c, :] = image[:, ::c] = 200  # grid lines
        image[-1, :] = image[:, -1] = 200
        for x, y in self._walls:
            image[y * c:(y + 1) * c, x * c:(x + 1) * c] = 60
        yy, xx = np.mgrid[0:c, 0:c]
        middle = (c - 1) / 2
        disc = (xx - middle) ** 2 + (yy - middle) ** 2 <= (0.36 * c) ** 2
        edge = max(1, c // 8)
        inner = (xx >= edge) & (xx < c - edge) & (yy >= edge) & (yy < c - edge)
        outline = inner & ~((xx >= 2 * edge) & (xx < c - 2 * edge)
                            & (yy >= 2 * edge) & (yy < c - 2 * edge))
        colors = agent_colors(self.n_agents)
        for shape, xs, ys in ((outline, self._goal_x, self._goal_y), (disc, self._x, self._y)):
            for i, (x, y) in enumerate(zip(xs, ys)):
                image[y * c:(y + 1) * c, x * c:(x + 1) * c][shape] = colors[i]
        return image

    def _log_frame(self) -> None:
        import rerun as rr

        stream = self._rerun_stream()
        stream.set_time("step", sequence=self._frame)
        stream.set_time("episode", sequence=max(self._episode, 0))
        self._frame += 1
        goals = np.column_stack([self._goal_x, self._goal_y]).astype(np.float32)
        stream.log("world/goals", rr.Boxes2D(  # one half-size per box: Rerun draws one box
            centers=goals, half_sizes=np.full_like(goals, 0.4)))  # per half-size given
        stream.log("world/agents", rr.Points2D(
            np.column_stack([self._x, self._y]).astype(np.float32)))
        if self._walls:  # drawn as the swarm's recording draws them
            from nnql_swarm.recording.world import WALL_COLOUR, WALL_HALF, WALL_LINE, WALLS

            walls = np.array(self._walls, dtype=np.float32)
            stream.log(WALLS, rr.Boxes2D(centers=walls, half_sizes=np.full_like(walls, WALL_HALF),
                                         colors=[WALL_COLOUR], radii=WALL_LINE))

    def _rerun_stream(self):
        """The ``"human"`` mode's Rerun stream, opened on first use (module docstring)."""
        if self._stream is not None:
            return self._stream
        import rerun as rr

        from nnql_swarm.recording.palette import agent_colors

        stream = rr.RecordingStream("nnql-swarm-env")
        target = self.rerun_target
        if target is not None and str(target).startswith("rerun"):
            stream.connect_grpc(str(target))
        elif target is not None:
            Path(target).parent.mkdir(parents=True, exist_ok=True)
            stream.save(str(target))
        elif not sys.platform.startswith("linux") or os.environ.get("DISPLAY") \
                or os.environ.get("WAYLAND_DISPLAY"):
            stream.spawn()
        else:
            self.rerun_memory = stream.memory_recording()
            warnings.warn("render_mode='human' without a display: the frames stay in memory "
                          "(env.rerun_memory); pass rerun='frames.rrd' to save them (open with "
                          "nnql-view) or rerun='rerun+http://<host>:9876/proxy' to stream them to "
                          "a viewer", RuntimeWarning, stacklevel=3)
        xs = np.arange(self.width + 1) - 0.5
        ys = np.arange(self.height + 1) - 0.5
        lines = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
        stream.log("world/grid", rr.LineStrips2D(lines, colors=[90, 90, 90], radii=0.02),
                   static=True)
        colors = agent_colors(self.n_agents)
        stream.log("world/agents", rr.Points2D.from_fields(
            colors=colors, labels=self.possible_agents, radii=0.33, show_labels=True), static=True)
        stream.log("world/goals", rr.Boxes2D.from_fields(colors=colors, radii=0.06), static=True)
        self._stream = stream
        return stream

    def _observe(self, i: int) -> np.ndarray:
        x, y = self._x, self._y
        goal = offset_state(self._goal_x[i] - x[i], self._goal_y[i] - y[i])
        others = [offset_state(x[j] - x[i], y[j] - y[i]) if sees(x[i], y[i], x[j], y[j])
                  else NOT_IN_VIEW for j in range(self.n_agents) if j != i]
        return np.array([goal, *others], dtype=np.int64)
