"""A PettingZoo ``ParallelEnv`` over the world rules: N learning agents, each seeking its own goal.

## Description
A swarm episode (:func:`world.scenario.swarm_episode`): ``n_agents`` agents start on distinct cells
of a ``width x height`` grid, each with its own goal cell, all starts and goals distinct. Every
step all agents move at once and :func:`world.rules.world_step` resolves the moves: two agents
trying to occupy one cell collide and stay where they were (``world.rules``), and so do two agents
swapping cells when ``count_swaps`` is set (the default here, as in swarm mode).

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
Agents that have arrived stay parked on their goals and are still seen (and can still be run into).

## Rewards
Per step, the paper's two rewards added (:mod:`world.rules`): destination seeking ``1/d`` if the
Euclidean distance ``d`` to the goal decreased, ``0.5/d`` if it stayed, 0 if it grew, and
``GOAL_REWARD`` on arriving; plus collision avoidance ``CA_REWARD`` (10) without a collision, 0 with
one. ``infos[agent]`` holds the two parts (``reward_ds``, ``reward_ca``) and ``collided``.

## Negotiation
``infos[agent]["waits_for"]`` names the agents whose intents this agent would wait for before
its next step in the swarm's negotiation (``protocol.ranks.waits_for``: higher-ranked agents within
``negotiation_radius``, all of them or, with ``wait_rule="meet"``, those on their way that it could
meet on the next step; ranks rotating every step), so that a policy that reads intents can be
stepped in that order.

## Episode end
An agent is terminated when it reaches its goal, and then leaves ``agents``. Every agent still on its
way is truncated after ``max_steps`` steps.

## Seeding
``reset(seed=S)`` starts episode 0 of seed ``S``; each later ``reset()`` without a seed moves on to the
next episode of the same seed. Scenarios come from :mod:`protocol.seeding` streams, and the
dynamics draw nothing, so the same seed and actions give the same trajectory.
"""

import functools

import numpy as np
from gymnasium import spaces
from pettingzoo import ParallelEnv

from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, STAY, VIEW_RADIUS, offset_state, sees
from nnql_swarm.protocol.jit import flags, floats, ints, python_values
from nnql_swarm.protocol.ranks import WAIT_RULES, awaits_answer, priority_rank
from nnql_swarm.world.rules import GOAL_REWARD, ROW_FLOATS, ROW_INTS, STAY_REWARD, world_step
from nnql_swarm.world.scenario import swarm_episode

NOT_IN_VIEW = N_STATES
"""The observation slot value of another agent out of view."""


class SwarmGridEnv(ParallelEnv):
    """N agents on a grid, each reaching for its own goal while avoiding the others."""

    metadata = {"name": "nnql_swarm_grid_v0", "render_modes": ["ansi"], "is_parallelizable": True}

    def __init__(
        self,
        n_agents: int = 4,
        width: int = 11,
        height: int = 11,
        max_steps: int = 100,
        count_swaps: bool = True,
        goal_reward: float = GOAL_REWARD,
        negotiation_radius: int = VIEW_RADIUS,
        wait_rule: str = "reach",
        render_mode: str | None = None,
    ) -> None:
        if n_agents < 1:
            raise ValueError(f"need at least one agent, got {n_agents}")
        if 2 * n_agents > width * height:
            raise ValueError(f"{n_agents} agents need {2 * n_agents} cells; {width}x{height} has fewer")
        if wait_rule not in WAIT_RULES:
            raise ValueError(f"wait_rule must be one of {', '.join(WAIT_RULES)}, got {wait_rule!r}")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"unsupported render mode {render_mode!r}")
        self.n_agents = n_agents
        self.width, self.height = width, height
        self.max_steps = max_steps
        self.count_swaps = count_swaps
        self.goal_reward = goal_reward
        self.negotiation_radius = negotiation_radius
        self.meet_only = wait_rule == "meet"
        self.render_mode = render_mode
        self.possible_agents = [f"agent_{i}" for i in range(n_agents)]
        self.agents: list[str] = []
        self._index = {name: i for i, name in enumerate(self.possible_agents)}
        self._seed: int | None = None
        self._episode = -1
        self._x, self._y = [0] * n_agents, [0] * n_agents
        self._goal_x, self._goal_y = [0] * n_agents, [0] * n_agents
        self._arrived = [False] * n_agents
        self._steps = 0

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
                self._seed = int(np.random.SeedSequence().entropy % 2**63)
            self._episode += 1
        scenario = swarm_episode(self._seed, self._episode, self.width, self.height, self.n_agents)
        self._x, self._y = scenario.starts[:, 0].tolist(), scenario.starts[:, 1].tolist()
        self._goal_x, self._goal_y = scenario.goals[:, 0].tolist(), scenario.goals[:, 1].tolist()
        self._arrived = [False] * self.n_agents
        self._steps = 0
        self.agents = list(self.possible_agents)
        observations = {agent: self._observe(self._index[agent]) for agent in self.agents}
        return observations, {agent: {} for agent in self.agents}

    def step(self, actions: dict):
        live = list(self.agents)
        n = self.n_agents
        chosen = [STAY] * n  # parked agents stay
        for agent in live:
            chosen[self._index[agent]] = int(actions.get(agent, STAY))
        x, y, arrived = ints(self._x), ints(self._y), flags(self._arrived)
        collided, r_ds, r_ca = flags([False] * n), floats([0.0] * n), floats([0.0] * n)
        world_step(x, y, ints(self._goal_x), ints(self._goal_y), flags([True] * n), arrived,
                   ints(chosen), n, self.width, self.height, self.count_swaps, self.goal_reward,
                   STAY_REWARD, ints([0] * n), ints([0] * n), collided, r_ds, r_ca,
                   ints([0] * (self.width * self.height)), flags([False] * n),
                   ints([0] * ROW_INTS), floats([0.0] * ROW_FLOATS))
        self._x, self._y, self._arrived = python_values(x), python_values(y), python_values(arrived)
        collided, reward_ds, reward_ca = map(python_values, (collided, r_ds, r_ca))
        self._steps += 1

        observations, rewards, terminations, truncations, infos = {}, {}, {}, {}, {}
        for agent in live:
            i = self._index[agent]
            observations[agent] = self._observe(i)
            rewards[agent] = reward_ds[i] + reward_ca[i]
            terminations[agent] = self._arrived[i]
            truncations[agent] = self._steps >= self.max_steps and not self._arrived[i]
            infos[agent] = {"reward_ds": reward_ds[i], "reward_ca": reward_ca[i],
                            "collided": collided[i], "waits_for": self._waits_for(i)}
        self.agents = [a for a in live if not (terminations[a] or truncations[a])]
        return observations, rewards, terminations, truncations, infos

    def _waits_for(self, i: int) -> list[str]:
        """The agents whose intents agent ``i`` waits for before the next step."""
        n, step, x, y = self.n_agents, self._steps, self._x, self._y
        rank = priority_rank(i, step, n)
        return [self.possible_agents[j] for j in range(n)
                if j != i and awaits_answer(rank, priority_rank(j, step, n), x[i], y[i], x[j],
                                            y[j], self.negotiation_radius, self.meet_only,
                                            self._arrived[i], self._arrived[j])]

    def render(self) -> str | None:
        if self.render_mode != "ansi":
            return None
        rows = [["." for _ in range(self.width)] for _ in range(self.height)]
        for i, (x, y) in enumerate(zip(self._goal_x, self._goal_y)):
            rows[y][x] = chr(ord("a") + i % 26)
        for i, (x, y) in enumerate(zip(self._x, self._y)):
            rows[y][x] = chr(ord("A") + i % 26)
        return "\n".join("".join(row) for row in rows)

    def close(self) -> None:
        pass

    def _observe(self, i: int) -> np.ndarray:
        x, y = self._x, self._y
        goal = offset_state(self._goal_x[i] - x[i], self._goal_y[i] - y[i])
        others = [offset_state(x[j] - x[i], y[j] - y[i]) if sees(x[i], y[i], x[j], y[j])
                  else NOT_IN_VIEW for j in range(self.n_agents) if j != i]
        return np.array([goal, *others], dtype=np.int64)
