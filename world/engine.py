"""The swarm world, pure: positions, goals, the lockstep tick, observations out, intents in.

One tick: :meth:`SwarmWorld.observations` gives every agent its observation; the agents answer
with an action each (``None`` for an agent that missed the deadline: it stays, and the miss is
counted); :meth:`SwarmWorld.apply` moves everyone at once by ``world.rules`` and scores the tick.

Each episode ends with one extra *end tick*: every agent is told ``episode_end`` (with the rewards
of its last action), finishes its learning, checkpoints and answers STAY; nothing moves. An agent
that reaches its goal is *arrived*: it is parked on its goal, keeps answering STAY and is still an
obstacle to the others. The episode ends when every agent has arrived or after ``max_steps``.
"""

from dataclasses import dataclass

import numpy as np

from protocol.actions import STAY, in_view
from protocol.config import SwarmConfig, priority_rank
from protocol.messages import WORLD_SENDER, Observation
from world.rules import (
    arbitrate,
    collision_reward,
    destination_reward,
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


class SwarmWorld:
    """The lockstep world of a swarm run (every agent learns, each has its own goal)."""

    def __init__(self, config: SwarmConfig, first_episode: int = 0, first_tick: int = 0) -> None:
        """A world at the start of ``first_episode`` (``--resume`` starts after the last row)."""
        self.config = config
        self.tick = first_tick
        self.finished = False
        self.violations = 0
        self._start_episode(first_episode)

    def _start_episode(self, episode: int) -> None:
        c = self.config
        scenario = swarm_episode(c.seed, episode, c.width, c.height, c.n_agents)
        self.episode = episode
        self.step = 0
        self.positions = scenario.starts.copy()
        self.goals = scenario.goals
        self.arrived = np.zeros(c.n_agents, dtype=bool)
        self.ending = False
        self._r_ds = np.zeros(c.n_agents)
        self._r_ca = np.zeros(c.n_agents)
        self._collided = np.zeros(c.n_agents, dtype=bool)
        self._row = dict.fromkeys(EPISODE_FIELDS, 0)
        self._row.update(
            episode=episode,
            reward_sum=0.0,
            shortest_sum=int(shortest_steps(self.positions, self.goals).sum()),
        )

    def observations(self) -> list[Observation]:
        """Every agent's observation for the current tick, indexed by agent id."""
        c = self.config
        offsets = self.positions[None, :, :] - self.positions[:, None, :]
        visible = in_view(offsets) & ~np.eye(c.n_agents, dtype=bool)
        cells = self.positions.tolist()
        return [
            Observation(
                run=c.run_id,
                tick=self.tick,
                sender=WORLD_SENDER,
                agent=i,
                episode=self.episode,
                step=self.step,
                position=tuple(cells[i]),
                goal=tuple(self.goals[i].tolist()),
                neighbours=tuple((j, *cells[j]) for j in np.flatnonzero(visible[i]).tolist()),
                rank=priority_rank(i, self.tick, c.n_agents),
                reward_ds=float(self._r_ds[i]),
                reward_ca=float(self._r_ca[i]),
                collided=bool(self._collided[i]),
                arrived=bool(self.arrived[i]),
                episode_end=self.ending,
            )
            for i in range(c.n_agents)
        ]

    def apply(self, actions: list[int | None]) -> TickReport:
        """Apply every agent's action for this tick (``None``: missed, counted, stays)."""
        c = self.config
        missed = tuple(i for i, a in enumerate(actions) if a is None)
        if self.ending:
            self._row["end_tick"] = self.tick
            stays = (STAY,) * c.n_agents
            report = TickReport(self.tick, self.episode, False, stays, (), missed, (), dict(self._row))
            self.tick += 1
            if self.episode + 1 >= c.episodes:
                self.finished = True
            else:
                self._start_episode(self.episode + 1)
            return report

        chosen = np.array([STAY if a is None else a for a in actions], dtype=np.int64)
        chosen[self.arrived] = STAY
        before = self.positions
        after, collided = arbitrate(before[None], chosen[None], c.width, c.height, c.count_swaps)
        after, collided = after[0], collided[0]
        violations = tuple(invariant_violations(before, after, c.count_swaps))
        self.violations += len(violations)

        acting = ~self.arrived
        self._r_ds = np.where(acting, destination_reward(before, after, self.goals, c.goal_reward), 0.0)
        self._r_ca = np.where(acting, collision_reward(collided), 0.0)
        self._collided = collided
        self.positions = after
        self.arrived = self.arrived | np.all(after == self.goals, axis=-1)
        self.step += 1

        row = self._row
        row["steps"] = self.step
        row["collisions"] += int(collided.sum())
        row["missed_intents"] += len(missed)
        row["reward_sum"] += float(self._r_ds.sum() + self._r_ca.sum())
        row["arrived"] = int(self.arrived.sum())
        row["agent_steps"] += int(acting.sum())
        self.ending = bool(self.arrived.all()) or self.step >= c.max_steps
        report = TickReport(
            self.tick, self.episode, True, tuple(chosen.tolist()),
            tuple(np.flatnonzero(collided).tolist()), missed,
            violations, None,
        )
        self.tick += 1
        return report
