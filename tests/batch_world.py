"""The swarm world on the batch rules: the reference for :class:`world.engine.SwarmWorld`.

``SwarmWorld`` keeps plain-Python cells and plays a tick by the one-world rules of ``world.rules``
(``arbitrate_one`` and friends). :class:`BatchRulesWorld` is the world as it was before: numpy
state, the batch rules over a batch of one, visibility by ``in_view``, the reward sum by numpy.
It shares with ``SwarmWorld`` only what applies no rule (the end tick, the episode's row).
``tests/test_one_world.py`` checks that both give identical observations and reports;
``bench/world_tick.py`` times them.
"""

import numpy as np

from protocol.actions import STAY, in_view
from protocol.config import priority_rank
from protocol.messages import WORLD_SENDER, Observation
from world.engine import SwarmWorld, TickReport
from world.rules import (
    arbitrate, collision_reward, destination_reward, invariant_violations,
)


class BatchRulesWorld(SwarmWorld):
    """:class:`SwarmWorld` with numpy state and the batch rules (batch of one)."""

    @property
    def positions(self) -> np.ndarray:
        return self._positions

    @property
    def arrived(self) -> np.ndarray:
        return self._done

    def _start_episode(self, episode: int) -> None:
        super()._start_episode(episode)
        n = self.config.n_agents
        self._positions = np.array(self._cells, dtype=np.int64)
        self._done = np.zeros(n, dtype=bool)
        self._r_ds = np.zeros(n)
        self._r_ca = np.zeros(n)
        self._collided = np.zeros(n, dtype=bool)

    def observations(self) -> list[Observation]:
        c = self.config
        offsets = self._positions[None, :, :] - self._positions[:, None, :]
        visible = in_view(offsets) & ~np.eye(c.n_agents, dtype=bool)
        cells = self._positions.tolist()
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
                arrived=bool(self._done[i]),
                episode_end=self.ending,
            )
            for i in range(c.n_agents)
        ]

    def _move(self, actions: list[int | None], missed: tuple[int, ...]) -> TickReport:
        c = self.config
        chosen = np.array([STAY if a is None else a for a in actions], dtype=np.int64)
        chosen[self._done] = STAY
        before = self._positions
        after, collided = arbitrate(before[None], chosen[None], c.width, c.height, c.count_swaps)
        after, collided = after[0], collided[0]
        violations = tuple(invariant_violations(before, after, c.count_swaps))
        self.violations += len(violations)

        acting = ~self._done
        self._r_ds = np.where(acting, destination_reward(before, after, self.goals, c.goal_reward), 0.0)
        self._r_ca = np.where(acting, collision_reward(collided), 0.0)
        self._collided = collided
        self._positions = after
        self._done = self._done | np.all(after == self.goals, axis=-1)
        self.step += 1

        row = self._row
        row["steps"] = self.step
        row["collisions"] += int(collided.sum())
        row["missed_intents"] += len(missed)
        row["reward_sum"] += float(self._r_ds.sum() + self._r_ca.sum())
        row["arrived"] = int(self._done.sum())
        row["agent_steps"] += int(acting.sum())
        self.ending = bool(self._done.all()) or self.step >= c.max_steps
        report = TickReport(
            self.tick, self.episode, True, tuple(chosen.tolist()),
            tuple(np.flatnonzero(collided).tolist()), missed,
            violations, None,
        )
        self.tick += 1
        return report
