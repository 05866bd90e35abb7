"""The swarm world, pure: positions, goals, the lockstep tick, observations out, intents in.

One tick: :meth:`SwarmWorld.observations` gives every agent its observation; the agents answer
with an action each (``None`` for an agent that missed the deadline: it stays, and the miss is
counted); :meth:`SwarmWorld.apply` moves everyone at once by ``world.rules`` and scores the tick.

Each episode ends with one extra *end tick*: every agent is told ``episode_end`` (with the rewards
of its last action), finishes its learning, checkpoints and answers STAY; nothing moves. An agent
that reaches its goal is *arrived*: it is parked on its goal, keeps answering STAY and is still an
obstacle to the others. The episode ends when every agent has arrived or after ``max_steps``.

The world is one world, and both calls sit on the swarm's critical path (between the last
agent's intent and the next observations), so it keeps its state as plain Python cells and uses
the one-world rules of ``world.rules`` (``arbitrate_one`` and friends), not the batch ones, whose
numpy calls cost more than their arithmetic on a handful of agents. Results are bit for bit those
of the batch rules (``tests/test_one_world.py``); ``bench/world_tick.py`` measures the gain.
"""

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from protocol.actions import STAY, VIEW_RADIUS, sees
from protocol.config import SwarmConfig, priority_rank
from protocol.messages import WORLD_SENDER, Observation
from world.rules import (
    Cell,
    arbitrate_one,
    collision_reward_of,
    destination_reward_of,
    invariant_violations,
    shortest_steps,
)
from world.scenario import swarm_episode

EPISODE_FIELDS = (
    "episode", "steps", "collisions", "missed_intents", "reward_sum", "arrived", "shortest_sum",
    "agent_steps", "end_tick",
)
"""The deterministic columns of ``episodes.csv``, one row per episode."""


@dataclass(frozen=True)
class TickReport:
    """What one tick did: the actions applied, who collided, the finished episode's row, if any."""

    tick: int
    episode: int
    moved: bool
    actions: tuple[int, ...]
    collided: tuple[int, ...]
    missed: tuple[int, ...]
    violations: tuple[str, ...]
    episode_row: dict | None


def summed_like_numpy(values: list[float]) -> float:
    """``float(np.sum(np.array(values)))``, bit for bit, in plain Python.

    numpy adds float64 pairwise: fewer than 8 values one after the other; up to 128 into eight
    interleaved partial sums, added as a tree, then the rest one after the other; more than 128
    as two halves (split at a multiple of 8); and the reduction starts from 0.0. (Python's
    ``sum`` of floats is no substitute: from 3.12 on it compensates rounding errors.)
    """
    return 0.0 + _pairwise_sum(values)


def _pairwise_sum(values: list[float]) -> float:
    """numpy's ``pairwise_sum`` of float64 (``loops_utils.h.src``), step for step."""
    n = len(values)
    if n > 128:
        half = n // 2 - n // 2 % 8
        return _pairwise_sum(values[:half]) + _pairwise_sum(values[half:])
    if n < 8:
        total = 0.0
        rest = values
    else:
        whole = n - n % 8
        r = values[:8]
        for start in range(8, whole, 8):
            for k in range(8):
                r[k] += values[start + k]
        total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
        rest = values[whole:]
    for value in rest:
        total += value
    return total


class SwarmWorld:
    """The lockstep world of a swarm run (every agent learns, each has its own goal)."""

    def __init__(self, config: SwarmConfig, first_episode: int = 0, first_tick: int = 0) -> None:
        """A world at the start of ``first_episode`` (``--resume`` starts after the last row)."""
        self.config = config
        self.tick = first_tick
        self.finished = False
        self.violations = 0
        # On a grid that fits in the egocentric window, everybody always sees everybody.
        self._sees_all = max(config.width, config.height) <= VIEW_RADIUS + 1
        self._start_episode(first_episode)

    @property
    def positions(self) -> np.ndarray:
        """Every agent's cell, ``(N, 2)``: a new array each time."""
        return np.array(self._cells, dtype=np.int64)

    @property
    def cells(self) -> tuple[Cell, ...]:
        """Every agent's cell as ``(x, y)``, by agent id."""
        return tuple(self._cells)

    @property
    def arrived_flags(self) -> tuple[bool, ...]:
        """Whether each agent has arrived, by agent id."""
        return tuple(self._arrived)

    @property
    def arrived(self) -> np.ndarray:
        """Whether each agent has arrived, ``(N,)``: a new array each time."""
        return np.array(self._arrived, dtype=bool)

    def _start_episode(self, episode: int) -> None:
        c = self.config
        scenario = swarm_episode(c.seed, episode, c.width, c.height, c.n_agents)
        self.episode = episode
        self.step = 0
        self.goals = scenario.goals
        self.ending = False
        self._cells: list[Cell] = [tuple(cell) for cell in scenario.starts.tolist()]
        self._goal_cells: list[Cell] = [tuple(cell) for cell in scenario.goals.tolist()]
        self._arrived = [False] * c.n_agents
        self._r_ds = [0.0] * c.n_agents
        self._r_ca = [0.0] * c.n_agents
        self._collided = [False] * c.n_agents
        self._row = dict.fromkeys(EPISODE_FIELDS, 0)
        self._row.update(
            episode=episode,
            reward_sum=0.0,
            shortest_sum=int(shortest_steps(scenario.starts, scenario.goals).sum()),
        )

    def observations(self) -> list[Observation]:
        """Every agent's observation for the current tick, indexed by agent id."""
        neighbours = self._neighbours()
        return [self._observation(i, neighbours[i]) for i in range(self.config.n_agents)]

    def observations_by_rank(self) -> Iterator[Observation]:
        """The observations in rank order, each built only when the one before it is taken: the
        world sends the first to decide its observation before it builds the others'."""
        n, tick = self.config.n_agents, self.tick
        neighbours = self._neighbours()
        for rank in range(n):
            agent = (rank + tick) % n  # the inverse of priority_rank
            yield self._observation(agent, neighbours[agent])

    def _observation(self, i: int, neighbours: tuple[tuple[int, int, int], ...]) -> Observation:
        c = self.config
        # Positional, in Observation's field order: keywords cost a fifth of this call.
        return Observation(c.run_id, self.tick, WORLD_SENDER, i, self.episode, self.step,
                           self._cells[i], self._goal_cells[i], neighbours,
                           priority_rank(i, self.tick, c.n_agents), self._r_ds[i], self._r_ca[i],
                           self._collided[i], self._arrived[i], self.ending)

    def _neighbours(self) -> list[tuple[tuple[int, int, int], ...]]:
        """Each agent's visible others as ``(id, x, y)`` in id order, by agent id."""
        cells = self._cells
        everyone = tuple((j, x, y) for j, (x, y) in enumerate(cells))
        if self._sees_all:
            return [everyone[:i] + everyone[i + 1:] for i in range(len(cells))]
        seen: list[list[tuple[int, int, int]]] = [[] for _ in cells]
        for i, cell in enumerate(cells):  # each pair once: seeing is mutual
            for j in range(i + 1, len(cells)):
                if sees(cell, cells[j]):
                    seen[i].append(everyone[j])
                    seen[j].append(everyone[i])
        return [tuple(others) for others in seen]

    def apply(self, actions: list[int | None]) -> TickReport:
        """Apply every agent's action for this tick (``None``: missed, counted, stays)."""
        missed = tuple(i for i, a in enumerate(actions) if a is None)
        if self.ending:
            return self._end_tick(missed)
        return self._move(actions, missed)

    def _end_tick(self, missed: tuple[int, ...]) -> TickReport:
        """The episode's end tick: nothing moves; the row is final; the next episode starts."""
        c = self.config
        self._row["end_tick"] = self.tick
        stays = (STAY,) * c.n_agents
        report = TickReport(self.tick, self.episode, False, stays, (), missed, (), dict(self._row))
        self.tick += 1
        if self.episode + 1 >= c.episodes:
            self.finished = True
        else:
            self._start_episode(self.episode + 1)
        return report

    def _move(self, actions: list[int | None], missed: tuple[int, ...]) -> TickReport:
        """A step of the episode: everyone moves at once; rewards, arrivals and the row."""
        c = self.config
        acting = [not done for done in self._arrived]
        chosen = tuple(a if a is not None and go else STAY for a, go in zip(actions, acting))
        before, goals = self._cells, self._goal_cells
        after, collided = arbitrate_one(before, chosen, c.width, c.height, c.count_swaps)
        violations = tuple(invariant_violations(before, after, c.count_swaps))
        self.violations += len(violations)

        self._r_ds = [destination_reward_of(old, new, goal, c.goal_reward) if go else 0.0
                      for old, new, goal, go in zip(before, after, goals, acting)]
        self._r_ca = [collision_reward_of(hit) if go else 0.0 for hit, go in zip(collided, acting)]
        self._collided = collided
        self._cells = after
        self._arrived = [not go or new == goal for new, goal, go in zip(after, goals, acting)]
        self.step += 1

        row = self._row
        row["steps"] = self.step
        row["collisions"] += sum(collided)
        row["missed_intents"] += len(missed)
        row["reward_sum"] += summed_like_numpy(self._r_ds) + summed_like_numpy(self._r_ca)
        row["arrived"] = sum(self._arrived)
        row["agent_steps"] += sum(acting)
        self.ending = all(self._arrived) or self.step >= c.max_steps
        report = TickReport(
            self.tick, self.episode, True, chosen,
            tuple(i for i, hit in enumerate(collided) if hit), missed,
            violations, None,
        )
        self.tick += 1
        return report
