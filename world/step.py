"""A step of an episode as the world plays it, once: the moves (``world.rules.world_step``), the
reward a refused first choice earns under priority inheritance, a lifelong run's next goals, and
the invariants checked after.

:func:`play_step` is what the swarm simulator (``sim.episode``) runs compiled, and what the world
process (``world.engine``) runs, through :func:`world_move`: the same step over flat arguments, so
that it can be compiled ahead of time (``world.rules_ahead``) for the world process, which runs
no numba (``protocol.jit``).
"""

from nnql_swarm.protocol.jit import kernel
from nnql_swarm.world.rules import (
    Bodies, Outcome, Rules, Scratch, Score, refusal_rewards, shared_cells, swaps_through,
    world_step,
)
from nnql_swarm.world.tasks import renew_goals

MOVE_EVERYONE, MOVE_SHARED, MOVE_SWAPPED = 0, 1, 2
"""What :func:`world_move` writes into its ``out``: whether every learner is on its goal, how
many bodies share a cell, how many passed through another (``world.rules``)."""
MOVE_FIELDS = 3


@kernel
def play_step(rules, bodies, actions, outcome, scratch, score, learners, refuse, ranks, lifelong,
              tasks, task_count, next_goal, reached):
    """One step of an episode (``world.rules.world_step``; ``actions`` are overwritten with the
    actions applied), then: under priority inheritance (``refuse``) the reward of a refused first
    choice (``world.rules.refusal_rewards``, over ``ranks``); in a lifelong run (``lifelong``)
    who reached a goal into ``reached`` (one flag per learner) and every such learner's next goal
    (``world.tasks.renew_goals``, from ``tasks``: ``task_count`` a learner); then the invariants
    (``world.rules.shared_cells``, and ``swaps_through`` where swaps count). Returns whether every
    learner is on its goal, and the two invariants' counts."""
    everyone = world_step(rules, bodies, actions, outcome, scratch, score)
    if refuse:
        refusal_rewards(ranks, actions, bodies.learns, learners, outcome.r_ca, score.row_f)
    if lifelong:
        for i in range(learners):
            reached[i] = bodies.arrived[i]
        renew_goals(bodies.goal_x, bodies.goal_y, bodies.arrived, learners, tasks, task_count,
                    next_goal, score.row)
    shared = shared_cells(bodies.x, bodies.y, rules.n, rules.width, scratch.occupancy)
    swapped = 0
    if rules.count_swaps:
        swapped = swaps_through(outcome.before_x, outcome.before_y, bodies.x, bodies.y, rules.n,
                                rules.width, scratch.occupancy)
    return everyone, shared, swapped


@kernel
def world_move(n, width, height, count_swaps, step_aside, goal_reward, stay_reward, x, y,
               goal_x, goal_y, learns, arrived, arrival, actions, before_x, before_y, collided,
               r_ds, r_ca, occupancy, blocked, row, row_f, learners, refuse, ranks, lifelong,
               tasks, task_count, next_goal, reached, out):
    """:func:`play_step` over flat arguments (the fields of ``world.rules``' named tuples, in
    their order), its results into ``out`` (``MOVE_*``)."""
    everyone, shared, swapped = play_step(
        Rules(n, width, height, count_swaps, step_aside, goal_reward, stay_reward),
        Bodies(x, y, goal_x, goal_y, learns, arrived, arrival), actions,
        Outcome(before_x, before_y, collided, r_ds, r_ca), Scratch(occupancy, blocked),
        Score(row, row_f), learners, refuse, ranks, lifelong, tasks, task_count, next_goal,
        reached)
    out[MOVE_EVERYONE] = 1 if everyone else 0
    out[MOVE_SHARED] = shared
    out[MOVE_SWAPPED] = swapped


MOVE_SIGNATURE = ("void(i8, i8, i8, b1, b1, f8, f8, i8[::1], i8[::1], i8[::1], i8[::1], b1[::1], "
                  "b1[::1], i8[::1], i8[::1], i8[::1], i8[::1], b1[::1], f8[::1], f8[::1], "
                  "i8[::1], b1[::1], i8[::1], f8[::1], i8, b1, i8[::1], b1, i8[::1], i8, i8[::1], "
                  "b1[::1], i8[::1])")
""":func:`world_move`'s types, as compiled ahead of time (``world.rules_ahead``): every buffer
a C-contiguous numpy array, integers ``int64``, flags ``bool``, rewards ``float64``."""
