"""Lifelong tasks (``--tasks lifelong``): an agent that reaches its goal is given the next one at
once, and what counts is how many goals the swarm reaches a step (throughput).

Each agent's goals of an episode are drawn ahead (:func:`goal_sequences`), from its own
generator (``protocol.seeding.task_rng``: the run's seed, the episode, the agent), as POGEMA
draws them: each uniformly from the free cells of the region the agent is in, never the goal it
has just reached. (POGEMA draws each goal when the agent arrives, from one generator per agent
for the whole run; ours are drawn per episode, so that an episode's goals depend on nothing
before it and a resumed run draws them again as they were.) An agent reaches at most one goal a
step, so ``max_steps`` goals each are enough. With a scenario (``--scen``) the first goals are
the scenario's; with a lifelong instance (``--goals``, POGEMA's published ones in
``maps/pogema/*/lifelong``) the goals it lists come first, and the rest are drawn.

:func:`renew_goals` is the world's rule, written once: the world process (``world.engine``) and
the simulator (``sim.episode``) call it after every step (``world.rules.world_step``), which
marks the agents that reached their goals as arrived; it hands each of them its next goal, counts
the goal reached, and the agent is on its way again.
"""

import numpy as np

from nnql_swarm.protocol.jit import kernel
from nnql_swarm.protocol.seeding import task_rng
from nnql_swarm.protocol.walls import regions
from nnql_swarm.world.rules import ROW_ARRIVED, ROW_GOALS


def goal_sequences(seed: int, episode: int, width: int, height: int, walls: np.ndarray,
                   goals: np.ndarray, count: int, given: tuple = ()) -> np.ndarray:
    """Every agent's next ``count`` goals after ``goals`` (its first, ``(N, 2)``): ``(N, count,
    2)`` cells ``(x, y)``: those ``given`` for it (``SwarmConfig.goal_lists``), then each drawn
    uniformly from the free cells of the agent's region, never the one before it (see the
    module docstring)."""
    region = regions(width, height, walls)
    sequences = np.zeros((len(goals), count, 2), dtype=np.int64)
    for agent, (gx, gy) in enumerate(goals.tolist()):
        listed = np.array(given[agent] if given else (), dtype=np.int64).reshape(-1, 2)[:count]
        sequences[agent, :len(listed)] = listed
        if len(listed):
            gx, gy = listed[-1].tolist()
        cells = np.flatnonzero(region == region[gy * width + gx])
        rng = task_rng(seed, episode, agent)
        drawn = count - len(listed)
        draws = rng.integers(0, len(cells) - 1, size=drawn) if len(cells) > 1 else \
            np.zeros(drawn, dtype=np.int64)
        at = int(np.searchsorted(cells, gy * width + gx))
        for k, draw in enumerate(draws.tolist(), start=len(listed)):
            if len(cells) > 1:
                at = draw + (draw >= at)  # uniform over the region without the goal just reached
            sequences[agent, k] = cells[at] % width, cells[at] // width
    return sequences


@kernel
def renew_goals(goal_x, goal_y, arrived, learners, sequences, count, next_goal, row):
    """Give every learner that has arrived its next goal (``sequences``: ``count`` goals per
    learner, flat, ``(i * count + k) * 2`` its ``k``-th cell; ``next_goal``: the next one's
    ``k``): it is no longer arrived, and the goal counts as reached (``row``'s ``ROW_GOALS``)."""
    for i in range(learners):
        if arrived[i]:
            arrived[i] = False
            row[ROW_ARRIVED] -= 1
            row[ROW_GOALS] += 1
            k = next_goal[i]
            at = (i * count + k) * 2
            goal_x[i] = sequences[at]
            goal_y[i] = sequences[at + 1]
            next_goal[i] = k + 1
