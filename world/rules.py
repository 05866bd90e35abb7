"""The world's rules, once: simultaneous moves, collisions, rewards and the end of an episode.

Kernel functions (``protocol.jit``) over one world's buffers, indexed by body (agent) id: the
world process calls them on Python lists, the swarm simulator compiled on rows of its arrays.

Collision rules:

- All intents of a tick are applied at once. A move off the grid aims at the current cell: the
  body stays, and that is no collision.
- A collision is two bodies trying to occupy the same cell in the same step: two moving into one
  cell, or one moving into a cell whose occupant stays or is blocked. Blocking propagates along
  chains until nothing changes (a fixed point): A -> B's cell, B -> C's cell, C stays blocks B,
  which then blocks A.
- Rotations (cycles of four or more bodies; a grid has no cycle of three) all move. Two bodies
  swapping cells pass through each other unless ``count_swaps`` is set; then both are blocked and
  both collide.
- Colliding bodies stay where they were. Every body of a conflicting pair is marked collided, the
  one that stays included (it was hit); each counts one collision per step, however many it met.

Rewards (the paper's, Section 4.1): destination seeking ``1/d`` if the Euclidean distance ``d``
to the goal decreased, ``0.5/d`` if it stayed the same, 0 if it grew, and ``goal_reward`` on
arriving (the paper leaves it open); collision avoidance 10 without a collision, 0 with one. On a
grid every move changes the distance, so "the same distance" means the body did not move (it
stayed, was blocked or bumped the edge): ``stay_reward`` (the paper's 0.5) is what waiting earns.

Bodies are learners, each with its own goal, or scripted obstacles (the paper's experiment), which
have no goal, earn nothing and are not counted. A learner that reaches its goal has *arrived*.
What it does then is the on-target rule (``protocol.config.ON_TARGET``; ``step_aside`` below
says whether the second holds):

- ``park`` (the paper's reading): it stays on its goal for the rest of the episode whatever it
  says, and is still an obstacle.
- ``step-aside`` (the field's, POGEMA's ``on_target`` "nothing"): it stays on its goal by
  choice, and may leave it to make way; it counts as arrived only while it stands there, and
  its arrival step is its last. A step taken while arrived earns no reward (it is no learned
  move), whether it stays or steps aside.

Either way ``arrival[i]`` holds the step (1-based, of the episode) on which learner ``i`` last
reached its goal, valid while it has arrived, and the running score's learner-steps add up, over
the learners that have arrived, their arrival steps (over the others, the steps played). The
episode is over when every learner has arrived at once (or, the caller's business, after its
last step).

The field's metrics (POGEMA's, :func:`field_costs`) read each learner's *arrival step*: the step
(counted from 1) at which it last stepped onto its goal, 0 if it never did.
"""

import math
from typing import NamedTuple

from nnql_swarm.protocol.actions import N_ACTIONS, STAY, target_x, target_y
from nnql_swarm.protocol.jit import Buffer, kernel

Cell = tuple[int, int]

GOAL_REWARD = 10.0
"""The destination-seeking reward on arriving (the paper leaves it open; docs/paper.md)."""

STAY_REWARD = 0.5
"""The paper's destination-seeking reward, times ``d``, for a step that kept the distance."""

CA_REWARD = 10.0
"""The collision-avoidance reward for a step without collision (0 with one), as in the paper."""

ROW_STEPS, ROW_COLLISIONS, ROW_ARRIVED, ROW_AGENT_STEPS, ROW_GOALS = 0, 1, 2, 3, 4
"""Integer fields of an episode's running score (``row``): ticks moved, learners in a collision
(summed over steps), learners arrived, learner-steps spent before arriving (each learner's
last arrival step), and goals reached (lifelong runs, ``world.tasks``)."""
ROW_INTS = 5

ROW_REWARD, ROW_REWARD_DS, ROW_REWARD_CA = 0, 1, 2
"""Float fields of an episode's running score (``row_f``): the sum of both rewards, and each."""
ROW_FLOATS = 3


class Rules(NamedTuple):
    """The world's options for a run: how many bodies, the grid, whether swaps count, the
    on-target rule (``step-aside`` or not) and the destination-seeking rewards."""
    n: int
    width: int
    height: int
    count_swaps: bool
    step_aside: bool
    goal_reward: float
    stay_reward: float


class Bodies(NamedTuple):
    """The bodies' state, one entry per body: cell, goal (-1 for a scripted body), whether it
    learns, whether it has arrived, and its arrival step."""
    x: Buffer
    y: Buffer
    goal_x: Buffer
    goal_y: Buffer
    learns: Buffer
    arrived: Buffer
    arrival: Buffer


class Outcome(NamedTuple):
    """What a step did to each body: the cell it started from, whether it collided, and its
    two rewards (destination seeking, collision avoidance)."""
    before_x: Buffer
    before_y: Buffer
    collided: Buffer
    r_ds: Buffer
    r_ca: Buffer


class Scratch(NamedTuple):
    """The step's working space: a zero per grid cell (``y * width + x``, left all zeros), and
    a flag per body."""
    occupancy: Buffer
    blocked: Buffer


class Score(NamedTuple):
    """An episode's running score: ``row`` (``ROW_*`` integers) and ``row_f`` (``ROW_*`` floats)."""
    row: Buffer
    row_f: Buffer


@kernel
def arbitrate(x, y, actions, n, width, height, count_swaps, final_x, final_y, collided,
              occupancy, blocked):
    """Apply one tick of simultaneous moves: the final cells go to ``final_x``, ``final_y`` and
    who collided to ``collided``. ``x``, ``y`` hold ``n`` pairwise distinct cells.

    Scratch: ``occupancy`` has one zero per grid cell (``y * width + x``) and is left all zeros;
    ``blocked`` has ``n`` entries. A swapping pair (when swaps count) is blocked before the rounds:
    whoever aims at one of its cells meets one of the two either way, so the fixed point is the
    one that blocking it within a round gives.
    """
    for i in range(n):
        final_x[i] = target_x(x[i], actions[i], width)
        final_y[i] = target_y(y[i], actions[i], height)
        collided[i] = False
        blocked[i] = False
    if count_swaps:
        for i in range(n):
            occupancy[y[i] * width + x[i]] = i + 1
        for i in range(n):
            j = occupancy[final_y[i] * width + final_x[i]] - 1
            if j >= 0 and j != i and final_x[j] == x[i] and final_y[j] == y[i]:
                blocked[i] = True
        for i in range(n):
            occupancy[y[i] * width + x[i]] = 0
    while True:
        for i in range(n):
            if blocked[i]:
                final_x[i] = x[i]
                final_y[i] = y[i]
                collided[i] = True
                blocked[i] = False
        for i in range(n):
            occupancy[final_y[i] * width + final_x[i]] += 1
        any_blocked = False
        for i in range(n):
            if occupancy[final_y[i] * width + final_x[i]] > 1:
                collided[i] = True
                if final_x[i] != x[i] or final_y[i] != y[i]:
                    blocked[i] = True
                    any_blocked = True
        for i in range(n):
            occupancy[final_y[i] * width + final_x[i]] = 0
        if not any_blocked:
            return


@kernel
def destination_reward(before_x, before_y, after_x, after_y, goal_x, goal_y, goal_reward,
                       stay_reward):
    """The destination-seeking reward of a move; distances are compared as exact integer
    squares, so "stayed the same" never depends on rounding."""
    d2_before = (goal_x - before_x) ** 2 + (goal_y - before_y) ** 2
    d2_after = (goal_x - after_x) ** 2 + (goal_y - after_y) ** 2
    if d2_after == 0:
        return goal_reward
    if d2_after > d2_before:
        return 0.0
    if d2_after < d2_before:
        return 1.0 / math.sqrt(d2_after)
    return stay_reward / math.sqrt(d2_after)


@kernel
def collision_reward(collided):
    """The collision-avoidance reward: 10 without a collision, 0 with one."""
    return 0.0 if collided else CA_REWARD


@kernel
def shortest_steps(start_x, start_y, goal_x, goal_y):
    """The fewest moves from start to goal on an empty grid (Manhattan distance)."""
    return abs(goal_x - start_x) + abs(goal_y - start_y)


FIELD_COLUMNS = ("csr", "isr", "soc", "makespan")
"""The field's metrics of an episode (POGEMA's, :func:`field_columns`)."""


def field_columns(on_goal: int, soc: int, makespan: int, learners: int) -> dict:
    """The field's metrics of an episode from :func:`field_costs`: CSR (1 if every learner ends on
    its goal, else 0), ISR (the share that does), SoC and makespan."""
    return {"csr": int(on_goal == learners), "isr": on_goal / learners, "soc": soc,
            "makespan": makespan}


TASK_COLUMNS = ("goals", "throughput")
"""A lifelong run's measures of an episode (``world.tasks``; 0 in a one-shot run): goals reached,
and goals reached a step (the field's throughput)."""


def task_columns(goals: int, steps: int) -> dict:
    """The lifelong measures of an episode of ``steps`` steps that reached ``goals`` goals."""
    return {"goals": goals, "throughput": goals / steps if steps else 0.0}


@kernel
def field_costs(x, y, goal_x, goal_y, arrival, learners, steps):
    """The field's costs of an episode that ended after ``steps`` steps (POGEMA's): how many of
    the first ``learners`` bodies stand on their goal, the sum of their costs (SoC) and the largest
    (makespan). A learner's cost is its arrival step if it ends on its goal, else ``steps``."""
    on_goal = 0
    soc = 0
    makespan = 0
    for i in range(learners):
        cost = steps
        if x[i] == goal_x[i] and y[i] == goal_y[i]:
            on_goal += 1
            cost = arrival[i]
        soc += cost
        makespan = max(makespan, cost)
    return on_goal, soc, makespan


@kernel
def world_step(rules, bodies, actions, outcome, scratch, score):
    """One step of an episode: everyone moves at once; rewards, arrivals and the running score.

    ``actions`` are the bodies' intents, overwritten with the actions applied (under ``park``, a
    learner that has arrived stays whatever it says). The ``bodies``' cells, ``arrived`` and
    ``arrival`` are updated in place, the ``outcome`` written, the ``score`` advanced. Returns
    whether every learner is now on its goal.
    """
    n, width, height = rules.n, rules.width, rules.height
    step_aside, goal_reward, stay_reward = rules.step_aside, rules.goal_reward, rules.stay_reward
    x, y, goal_x, goal_y = bodies.x, bodies.y, bodies.goal_x, bodies.goal_y
    learns, arrived, arrival = bodies.learns, bodies.arrived, bodies.arrival
    before_x, before_y, collided = outcome.before_x, outcome.before_y, outcome.collided
    r_ds, r_ca = outcome.r_ds, outcome.r_ca
    occupancy, blocked = scratch.occupancy, scratch.blocked
    row, row_f = score.row, score.row_f
    for i in range(n):
        before_x[i] = x[i]
        before_y[i] = y[i]
        if learns[i] and arrived[i] and not step_aside:
            actions[i] = STAY
    arbitrate(before_x, before_y, actions, n, width, height, rules.count_swaps, x, y, collided,
              occupancy, blocked)
    step = row[ROW_STEPS] + 1
    ds_sum = 0.0
    ca_sum = 0.0
    everyone_arrived = True
    for i in range(n):
        if not learns[i]:
            r_ds[i] = 0.0
            r_ca[i] = 0.0
            continue
        if collided[i]:
            row[ROW_COLLISIONS] += 1
        on_goal = x[i] == goal_x[i] and y[i] == goal_y[i]
        if arrived[i]:
            r_ds[i] = 0.0
            r_ca[i] = 0.0
            if not on_goal:  # it made way: the steps since its arrival count again
                arrived[i] = False
                row[ROW_ARRIVED] -= 1
                row[ROW_AGENT_STEPS] += step - arrival[i]
        else:
            r_ds[i] = destination_reward(before_x[i], before_y[i], x[i], y[i],
                                         goal_x[i], goal_y[i], goal_reward, stay_reward)
            r_ca[i] = collision_reward(collided[i])
            row[ROW_AGENT_STEPS] += 1
            if on_goal:
                arrived[i] = True
                arrival[i] = step
                row[ROW_ARRIVED] += 1
        ds_sum += r_ds[i]
        ca_sum += r_ca[i]
        everyone_arrived = everyone_arrived and arrived[i]
    row[ROW_STEPS] += 1
    row_f[ROW_REWARD] += ds_sum + ca_sum
    row_f[ROW_REWARD_DS] += ds_sum
    row_f[ROW_REWARD_CA] += ca_sum
    return everyone_arrived


@kernel
def refusal_rewards(ranks, actions, learns, n, r_ca, row_f):
    """Under priority inheritance (``--arbitration pibt``) nobody collides, and the
    collision-avoidance reward reads the conflict the arbitration settled: a learner whose first
    choice (``ranks[i * N_ACTIONS + a]`` 0, ``world.pibt.plan``'s) was refused earns 0 for it,
    as for a collision, instead of ``CA_REWARD``. Runs after :func:`world_step` (``actions``
    applied, ``r_ca`` and the score's ``row_f`` written), over the first ``n`` bodies."""
    for i in range(n):
        if learns[i] and r_ca[i] == CA_REWARD and ranks[i * N_ACTIONS + actions[i]] != 0:
            r_ca[i] = 0.0
            row_f[ROW_REWARD] -= CA_REWARD
            row_f[ROW_REWARD_CA] -= CA_REWARD


@kernel
def shared_cells(x, y, n, width, occupancy):
    """How many bodies stand on a cell that another body stands on too (``occupancy``: zeros
    per grid cell, left all zeros)."""
    for i in range(n):
        occupancy[y[i] * width + x[i]] += 1
    shared = 0
    for i in range(n):
        if occupancy[y[i] * width + x[i]] > 1:
            shared += 1
    for i in range(n):
        occupancy[y[i] * width + x[i]] = 0
    return shared


@kernel
def swaps_through(before_x, before_y, x, y, n, width, occupancy):
    """How many bodies passed through another this step: each took the other's cell."""
    for i in range(n):
        occupancy[before_y[i] * width + before_x[i]] = i + 1
    swapped = 0
    for i in range(n):
        j = occupancy[y[i] * width + x[i]] - 1
        if j >= 0 and j != i and x[j] == before_x[i] and y[j] == before_y[i]:
            swapped += 1
    for i in range(n):
        occupancy[before_y[i] * width + before_x[i]] = 0
    return swapped
