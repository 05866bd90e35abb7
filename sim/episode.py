"""The whole swarm inside the kernel: world and every agent, many runs at once, episode by episode.

One call of :func:`run_episode` plays one episode of every run of a batch, each run on its own
(``prange`` spreads the runs over the cores; no run reads another's buffers, so the results do not
depend on how they are spread). A run is exactly what the distributed swarm plays for the same
options: at every tick the agents decide in rank order (``protocol.ranks``), each with the intents
of the higher-ranked neighbours it waits for, by the same learner (``learning.learner``); then the
world applies every move at once by the same rules (``world.rules``). Each episode ends with one
extra *end tick* in which nothing moves and every agent completes its last transition, as the
world's end tick does. Where a run shares one table among its agents, every agent's learning
record of a tick is applied in agent-id order before the next tick.

Bodies ``0 .. learners - 1`` learn; the rest are scripted obstacles whose every action is given
(the paper's experiment: one learner, three obstacles; a swarm's walls, ``protocol.walls``, whose
every action is to stay), outrank every learner and announce their scripted next action. An
oracle run plans every learner's move with PIBT (``world.pibt``, a reference planner) around the
walls, and learns nothing.

The arguments come grouped in named tuples (defined here, and ``world.rules``' for the world's
state): per-run options are the rows of :class:`Runs` (``params`` / ``params_f``, the learner's,
``learning.learner``, and ``options``, ``OPT_*``); the world's options (:class:`EpisodeRules`) are
the same for the whole batch.
"""

from typing import NamedTuple

from nnql_swarm.learning.fields import (
    FP_ALPHA, FP_GAMMA, LP_MEET_ONLY, LP_RADIUS, LP_READING, NB_NEXT_X, NB_NEXT_Y, NB_STATE_X,
    NB_STATE_Y, READ_DIR, READ_NNQL, Grid, LearnerBuffers, Sight,
)
from nnql_swarm.learning.learner import (
    announce_order, decide, finish, first_choice, make_way, planned_cell, preference_ranks,
)
from nnql_swarm.learning.neighbours import neighbour_row
from nnql_swarm.learning.record import apply_record, record_outcome
from nnql_swarm.protocol.actions import N_ACTIONS, STAY, sees
from nnql_swarm.protocol.jit import Buffer, batch_kernel, inline_kernel, kernel, prange
from nnql_swarm.protocol.ranks import SCRIPTED_RANK, priority_rank, waits_for
from nnql_swarm.world.pibt import plan
from nnql_swarm.world.rules import Bodies, Outcome, Rules, Scratch, Score, field_costs
from nnql_swarm.world.step import play_step

ORACLE_SCRATCH = 13
"""Rows of a run's oracle scratch (``world.pibt.plan``: occupant, reserved, order, blocked,
queue, stack, tried, the agents' priorities, probe, the nearest each has been to its goal, the
swap's partner and first-choice flag per chain level, and the goal each agent's distances are
for), a slot per grid cell each."""
ORACLE_GOAL_OF = 12

OPT_SHARED, OPT_LOOKAHEAD, OPT_ORACLE, OPT_WALLS, OPT_FROZEN, OPT_STEP_ASIDE = 0, 1, 2, 3, 4, 5
OPT_PIBT = 6
OPT_FIELDS = 7
"""Per-run options of the swarm: one table for all agents; the steps an announcement covers
(n of nnQL); the oracle instead of learners; whether the scripted bodies are walls (which a
learner's known map, ``learning.known_map``, learns as it sees them); frozen play (the tables are
read, never written; the learner's random step is off through its parameters); the
``step-aside`` on-target rule (``world.rules``: an arrived agent makes way,
``learning.learner.make_way``, and is nobody's arrived obstacle); priority inheritance over the
learners' announced orders (``--arbitration pibt``, ``world.pibt.plan``)."""

OUT_END_TICK, OUT_SHORTEST, OUT_VIOLATIONS, OUT_ON_GOAL, OUT_SOC, OUT_MAKESPAN = 0, 1, 2, 3, 4, 5
OUT_FIELDS = 6
"""Per-run results of an episode beside its score: the end tick, the sum of the learners' shortest
paths, broken invariants (shared cells, swap-throughs where swaps count), and the field's costs
(``world.rules.field_costs``: learners on their goal at the end, SoC, makespan)."""

TR_X, TR_Y, TR_ACTION, TR_COLLIDED, TR_ARRIVED, TR_WANTED, TR_GOAL_X, TR_GOAL_Y = range(8)
TR_FIELDS = 8
"""A recorded tick, per body: the cell it started from, the action applied, whether it collided,
whether it had arrived when the tick started, its first choice (the action it announced; under
``--arbitration pibt`` the arbitration may have applied another), and its goal when the tick
started (a lifelong run's change)."""


class EpisodeRules(NamedTuple):
    """What every run of a batch plays by: bodies (the first ``learners`` learn), grid, the
    episode's longest, whether swaps count, the destination-seeking rewards, whether the
    ticks are recorded (``Results.trace``), and whether an agent is given a new goal on reaching
    one (lifelong, ``world.tasks``: ``task_count`` goals each, ``Scenario.tasks``)."""
    n: int
    learners: int
    width: int
    height: int
    max_steps: int
    count_swaps: bool
    goal_reward: float
    stay_reward: float
    record: bool
    lifelong: bool
    task_count: int


class Runs(NamedTuple):
    """Each run's options, a row each: the learner's ``params`` and ``params_f``, the swarm's
    ``options`` (``OPT_*``), which seed's scenario and noise it plays, and its global tick
    (advanced in place)."""
    params: Buffer
    params_f: Buffer
    options: Buffer
    seed_of_run: Buffer
    tick: Buffer


class Learners(NamedTuple):
    """The learners' buffers, per run (``learning.fields.LearnerBuffers``, per agent): tables
    (one per agent, or the first the swarm's one), states, known maps, learning records and
    whether each waits to be applied (shared tables), the actions' values and the neighbour
    rows (scratch)."""
    q_ds: Buffer
    q_ca: Buffer
    state: Buffer
    state_f: Buffer
    wmap: Buffer
    rec: Buffer
    rec_f: Buffer
    pending_rec: Buffer
    values: Buffer
    nb: Buffer


class Scenario(NamedTuple):
    """An episode's scenario, per seed: every body's start, the learners' goals, the scripted
    bodies' actions per step, the learners' shortest paths, and in a lifelong run their next
    goals (``world.tasks.goal_sequences``, flat)."""
    starts: Buffer
    goals: Buffer
    scripts: Buffer
    paths: Buffer
    tasks: Buffer


class Noise(NamedTuple):
    """An episode's noise, per seed: each learner's exploring action and five tie-breakers per
    step (``learning.learner.draw_noise``)."""
    random_actions: Buffer
    ties: Buffer


class Moves(NamedTuple):
    """A tick's negotiation, per body: its action, whether it is fixed yet, its cell a tick
    ago (-1 at an episode's first), and in a lifelong run which of its goals comes next and
    whether it reached one this step (``world.step.play_step``)."""
    actions: Buffer
    decided: Buffer
    prev_x: Buffer
    prev_y: Buffer
    next_goal: Buffer
    reached: Buffer


class OracleScratch(NamedTuple):
    """The arbitration's working space (``world.pibt.plan``): ``ORACLE_SCRATCH`` rows of a slot
    per grid cell, a slot per body and cell, and the learners' announced orders (``ranks``, a
    slot per body and action)."""
    rows: Buffer
    cells: Buffer
    ranks: Buffer


class Results(NamedTuple):
    """An episode's results, per run: its running score (``world.rules.Score``), ``out``
    (``OUT_*``), and its recorded ticks (``TR_*`` per step and body, if recording)."""
    row: Buffer
    row_f: Buffer
    out: Buffer
    trace: Buffer


@kernel
def reads_intents(params):
    return params[LP_READING] == READ_NNQL or params[LP_READING] == READ_DIR


@kernel
def rank_of(i, tick, learners):
    """A body's negotiation rank: scripted obstacles outrank every learner."""
    return SCRIPTED_RANK if i >= learners else priority_rank(i, tick, learners)


@inline_kernel
def neighbour_rows(i, tick, rules, bodies, moves, q_ds, nb, params, options, announcing):
    """Fill ``nb`` with what agent ``i`` observes and has been told: its visible neighbours in
    id order. ``moves.decided``: bodies whose action of this tick is fixed; ``announcing``:
    whether anyone announces (not at an end tick). Under ``step-aside`` arrived agents are not
    parked. Returns the number of rows."""
    n, learners, width, height = rules.n, rules.learners, rules.width, rules.height
    x, y, goal_x, goal_y = bodies.x, bodies.y, bodies.goal_x, bodies.goal_y
    learns, arrived = bodies.learns, bodies.arrived
    actions, decided, prev_x, prev_y = moves.actions, moves.decided, moves.prev_x, moves.prev_y
    lookahead = options[OPT_LOOKAHEAD]
    shared = options[OPT_SHARED] != 0
    step_aside = options[OPT_STEP_ASIDE] != 0
    m = 0
    negotiates = announcing and reads_intents(params)
    rank = rank_of(i, tick, learners)
    for j in range(n):
        if j == i or not sees(x[i], y[i], x[j], y[j]):
            continue
        row = nb[m]
        known = (negotiates and decided[j]
                 and waits_for(True, rank, rank_of(j, tick, learners), x[i], y[i], x[j], y[j],
                               params[LP_RADIUS], params[LP_MEET_ONLY]))
        seen_before = prev_x[i] >= 0 and sees(prev_x[i], prev_y[i], prev_x[j], prev_y[j])
        neighbour_row(row, j, x[j], y[j], known, actions[j],
                      learns[j] and arrived[j] and not step_aside,
                      prev_x[j] if seen_before else -1, prev_y[j] if seen_before else -1,
                      width, height)
        if known and lookahead > 1 and learns[j]:
            t = 0 if shared else j
            sx, sy = planned_cell(q_ds[t], row[NB_NEXT_X], row[NB_NEXT_Y], goal_x[j], goal_y[j],
                                  lookahead - 1, width, height)
            row[NB_STATE_X] = sx
            row[NB_STATE_Y] = sy
        m += 1
    return m


@batch_kernel
def run_episode(rules, runs, agents, scenario, noise, bodies, moves, outcome, scratch,
                oracle_buffers, results):
    """Play one episode of every run (see the module docstring): every argument but ``rules``
    holds a row per run (``agents``: the learners' buffers; ``bodies.learns``, the same for every
    run, excepted), ``scenario`` and ``noise`` one per seed, and ``runs.seed_of_run`` says which
    seed's each run plays. Each run's global tick, tables and learner states are advanced in
    place."""
    for r in prange(runs.params.shape[0]):
        s = runs.seed_of_run[r]
        _episode(
            r, rules, runs,
            Learners(agents.q_ds[r], agents.q_ca[r], agents.state[r], agents.state_f[r],
                     agents.wmap[r], agents.rec[r], agents.rec_f[r], agents.pending_rec[r],
                     agents.values[r], agents.nb[r]),
            Scenario(scenario.starts[s], scenario.goals[s], scenario.scripts[s],
                     scenario.paths[s], scenario.tasks[s]),
            Noise(noise.random_actions[s], noise.ties[s]),
            Bodies(bodies.x[r], bodies.y[r], bodies.goal_x[r], bodies.goal_y[r], bodies.learns,
                   bodies.arrived[r], bodies.arrival[r]),
            Moves(moves.actions[r], moves.decided[r], moves.prev_x[r], moves.prev_y[r],
                  moves.next_goal[r], moves.reached[r]),
            Outcome(outcome.before_x[r], outcome.before_y[r], outcome.collided[r],
                    outcome.r_ds[r], outcome.r_ca[r]),
            Scratch(scratch.occupancy[r], scratch.blocked[r]),
            OracleScratch(oracle_buffers.rows[r], oracle_buffers.cells[r],
                          oracle_buffers.ranks[r]),
            Results(results.row[r], results.row_f[r], results.out[r], results.trace[r]))


@kernel
def _episode(r, rules, runs, agents, scenario, noise, bodies, moves, outcome, scratch,
             oracle_buffers, results):
    """One run's episode: ``runs`` the batch's, every other argument but ``rules`` this run's
    (``agents``: its learners' buffers)."""
    n, learners, width, height = rules.n, rules.learners, rules.width, rules.height
    max_steps, count_swaps, record = rules.max_steps, rules.count_swaps, rules.record
    params, params_f, options = runs.params[r], runs.params_f[r], runs.options[r]
    ticks = runs.tick
    q_ds, q_ca, state, state_f = agents.q_ds, agents.q_ca, agents.state, agents.state_f
    wmap, rec, rec_f, pending_rec = agents.wmap, agents.rec, agents.rec_f, agents.pending_rec
    values, nb = agents.values, agents.nb
    starts, goals, scripts, paths = (scenario.starts, scenario.goals, scenario.scripts,
                                     scenario.paths)
    random_actions, ties = noise.random_actions, noise.ties
    x, y, goal_x, goal_y = bodies.x, bodies.y, bodies.goal_x, bodies.goal_y
    arrived, arrival = bodies.arrived, bodies.arrival
    actions, decided, prev_x, prev_y = moves.actions, moves.decided, moves.prev_x, moves.prev_y
    collided, r_ds, r_ca = outcome.collided, outcome.r_ds, outcome.r_ca
    oracle_scratch, oracle_cells = oracle_buffers.rows, oracle_buffers.cells
    ranks = oracle_buffers.ranks
    row, row_f, out, trace = results.row, results.row_f, results.out, results.trace
    shared = options[OPT_SHARED] != 0
    learning = options[OPT_FROZEN] == 0
    oracle = options[OPT_ORACLE] != 0
    pibt = options[OPT_PIBT] != 0
    last_wall = n if options[OPT_WALLS] != 0 else learners  # walls: bodies learners .. n - 1
    step_aside = options[OPT_STEP_ASIDE] != 0
    lifelong = rules.lifelong
    next_goal = moves.next_goal
    alpha, gamma = params_f[FP_ALPHA], params_f[FP_GAMMA]
    world = Rules(n, width, height, count_swaps, step_aside, rules.goal_reward,
                  rules.stay_reward)
    score = Score(row, row_f)
    grid = Grid(width, height, x, y, learners, last_wall)
    shortest = 0
    for i in range(n):
        x[i] = starts[i, 0]
        y[i] = starts[i, 1]
        prev_x[i] = -1
        prev_y[i] = -1
        next_goal[i] = 0
        arrived[i] = False
        arrival[i] = 0
        collided[i] = False
        r_ds[i] = 0.0
        r_ca[i] = 0.0
        if i < learners:
            goal_x[i] = goals[i, 0]
            goal_y[i] = goals[i, 1]
            shortest += paths[i]
            if oracle or pibt:  # PIBT's first order: the farthest from its goal first
                oracle_scratch[7, i] = paths[i]
                oracle_scratch[9, i] = paths[i] + 1  # nearer than ever, at first
        else:
            goal_x[i] = -1
            goal_y[i] = -1
    for f in range(row.shape[0]):
        row[f] = 0
    for f in range(row_f.shape[0]):
        row_f[f] = 0.0
    out[OUT_SHORTEST] = shortest
    out[OUT_VIOLATIONS] = 0
    step = 0
    ending = False
    while True:
        tick = ticks[r]
        if shared:
            for i in range(learners):
                if pending_rec[i]:
                    apply_record(q_ds[0], q_ca[0], rec[i], rec_f[i], alpha, gamma)
                    pending_rec[i] = False
        for i in range(n):
            decided[i] = False
        for i in range(learners, n):  # scripted obstacles: their given actions, announced
            actions[i] = STAY if ending else scripts[step, i - learners]
            decided[i] = True
        if oracle and not ending:
            plan(x, y, goal_x, goal_y, arrived, n, learners, width, height, step_aside,
                 oracle_scratch[7],
                 oracle_scratch[9], actions, oracle_cells, oracle_scratch[0], oracle_scratch[1],
                 decided, oracle_scratch[2], oracle_scratch[3], oracle_scratch[4],
                 oracle_scratch[5], oracle_scratch[6], oracle_scratch[8], oracle_scratch[10],
                 oracle_scratch[11], step, oracle_scratch[ORACLE_GOAL_OF], False, ranks)
        for rank in range(learners):
            i = (rank + tick) % learners  # the agent of this rank (inverse of priority_rank)
            if oracle:
                if ending or (arrived[i] and not step_aside):
                    actions[i] = STAY
                decided[i] = True
                continue
            t = 0 if shared else i
            reached = arrived[i] or (lifelong and step > 0 and arrival[i] == step)
            record_outcome(state[i], state_f[i], r_ds[i], r_ca[i], reached)
            stops = ending or arrived[i]
            m = neighbour_rows(i, tick, rules, bodies, moves, q_ds, nb, params, options,
                               not stops)
            learner = LearnerBuffers(q_ds[t], q_ca[t], params, params_f, state[i], state_f[i],
                                     wmap[i], rec[i], rec_f[i], values)
            sight = Sight(x[i], y[i], goal_x[i], goal_y[i], nb, m, step == 0)
            if stops:
                written = finish(learner, grid, sight, learning and not shared)
                actions[i] = STAY
                if pibt and not ending:  # on its goal, it offers to stay; it may be pushed
                    preference_ranks(values, ties[i, step], wmap[i], x[i], y[i], width, height,
                                     STAY, False, ranks, i * N_ACTIONS, nb, m)
                elif step_aside and not ending:  # on its goal: it makes way if told to
                    m = neighbour_rows(i, tick, rules, bodies, moves, q_ds, nb, params, options,
                                       True)
                    sight = Sight(x[i], y[i], goal_x[i], goal_y[i], nb, m, False)
                    actions[i] = make_way(sight, learners, grid, ties[i, step])
            else:
                actions[i], written = decide(learner, grid, sight, random_actions[i, step],
                                             ties[i, step], learning and not shared)
                if pibt:
                    actions[i] = announce_order(learner, grid, sight, actions[i], ties[i, step],
                                                ranks, i * N_ACTIONS)
            pending_rec[i] = learning and shared and written
            decided[i] = True
        if pibt and not ending:  # the world settles the announced orders
            plan(x, y, goal_x, goal_y, arrived, n, learners, width, height, step_aside,
                 oracle_scratch[7], oracle_scratch[9], actions, oracle_cells, oracle_scratch[0],
                 oracle_scratch[1], decided, oracle_scratch[2], oracle_scratch[3],
                 oracle_scratch[4], oracle_scratch[5], oracle_scratch[6], oracle_scratch[8],
                 oracle_scratch[10], oracle_scratch[11], step, oracle_scratch[ORACLE_GOAL_OF],
                 True, ranks)
        if record:
            for i in range(n):
                trace[step, i, TR_X] = x[i]
                trace[step, i, TR_Y] = y[i]
                trace[step, i, TR_ARRIVED] = 1 if arrived[i] else 0
                trace[step, i, TR_GOAL_X] = goal_x[i]
                trace[step, i, TR_GOAL_Y] = goal_y[i]
                trace[step, i, TR_WANTED] = first_choice(ranks, i * N_ACTIONS) \
                    if pibt and i < learners and not ending else actions[i]
        if ending:
            if record:
                for i in range(n):
                    trace[step, i, TR_ACTION] = STAY
                    trace[step, i, TR_COLLIDED] = 0
            out[OUT_END_TICK] = tick
            out[OUT_ON_GOAL], out[OUT_SOC], out[OUT_MAKESPAN] = field_costs(
                x, y, goal_x, goal_y, arrival, learners, step)
            ticks[r] = tick + 1
            return
        for i in range(n):
            prev_x[i] = x[i]
            prev_y[i] = y[i]
        everyone, on_shared_cells, swapped = play_step(
            world, bodies, actions, outcome, scratch, score, learners, pibt, ranks, lifelong,
            scenario.tasks, rules.task_count, next_goal, moves.reached)
        out[OUT_VIOLATIONS] += on_shared_cells + swapped
        if record:
            for i in range(n):
                trace[step, i, TR_ACTION] = actions[i]
                trace[step, i, TR_COLLIDED] = 1 if collided[i] else 0
        step += 1
        ending = (everyone and not lifelong) or step >= max_steps
        ticks[r] = tick + 1
