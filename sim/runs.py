"""Driving the swarm simulator: runs described, their buffers made, their episodes played.

A run is one ``protocol.config.SwarmConfig``: its seed and learning options (the batch reads those;
the world's shape is the batch's :class:`World`); a :class:`Batch` holds many runs of one world
shape (bodies, grid, episode length) and plays them episode by episode through
``sim.episode.run_episode``. Every random draw comes from the run's seed: each episode's scenario
(starts, goals, scripts) from ``world.scenario``, each learner's exploring actions and tie-breakers
from its own stream (``protocol.seeding``), drawn per episode in the same order as an agent process
draws them. A run therefore gives exactly what it gives alone, in any batch, and what the
distributed swarm gives for the same options.
"""

import contextlib
from dataclasses import dataclass

import numpy as np

from nnql_swarm.learning.fields import (
    LF_FIELDS, LS_TAKEN, NB_FIELDS, READINGS, RF_FIELDS, VALUES_SIZE, ca_rows, learner_params,
    record_size, state_size,
)
from nnql_swarm.learning.known_map import check_cell_order, fresh_map, known_cells, map_size
from nnql_swarm.learning.learner import draw_noise
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, STAY
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import cached
from nnql_swarm.protocol.seeding import AGENT_STREAM, stream_rng
from nnql_swarm.protocol.walls import layout
from nnql_swarm.sim.episode import (
    OPT_FIELDS, OPT_FROZEN, OPT_LOOKAHEAD, OPT_ORACLE, OPT_PIBT, OPT_SHARED, OPT_STEP_ASIDE, OPT_WALLS,
    ORACLE_GOAL_OF, ORACLE_SCRATCH, OUT_END_TICK, OUT_FIELDS, OUT_MAKESPAN, OUT_ON_GOAL, OUT_SHORTEST, OUT_SOC,
    OUT_VIOLATIONS, TR_FIELDS, EpisodeRules, Learners, Moves, Noise, OracleScratch, Results, Runs,
    Scenario, run_episode,
)
from nnql_swarm.world.rules import (
    GOAL_REWARD, STAY_REWARD, ROW_AGENT_STEPS, ROW_ARRIVED, ROW_COLLISIONS, ROW_FLOATS, ROW_GOALS, ROW_INTS,
    ROW_REWARD, ROW_REWARD_CA, ROW_REWARD_DS, ROW_STEPS, Bodies, Outcome, Scratch, field_columns,
    task_columns,
)
from nnql_swarm.world.scenario import paper_episode, swarm_episode
from nnql_swarm.world.tasks import goal_sequences


@dataclass(frozen=True)
class World:
    """What every run of a batch shares: bodies (the first ``learners`` learn), grid, steps.

    The scripted bodies are the paper's obstacles or, at an ``obstacle_density`` above 0, the
    swarm's walls (each run's own, from its seed), or the walls of the map ``map_rows`` (every
    run's, with the fixed starts and goals of ``scenario`` if given)."""

    bodies: int
    learners: int
    width: int = 11
    height: int = 11
    max_steps: int = 100
    count_swaps: bool = True
    goal_reward: float = GOAL_REWARD
    stay_reward: float = STAY_REWARD
    obstacle_density: float = 0.0
    map_rows: tuple[str, ...] = ()
    scenario: tuple = ()
    lifelong: bool = False
    goal_lists: tuple = ()

    @property
    def scripted(self) -> int:
        return self.bodies - self.learners

    @property
    def paper(self) -> bool:
        """Whether the scripted bodies are the paper's obstacles (rather than walls)."""
        return self.scripted > 0 and not self.obstacle_density and not self.map_rows


def swarm_world(config: SwarmConfig) -> World:
    return World(bodies=config.n_bodies, learners=config.n_agents, width=config.width,
                 height=config.height, max_steps=config.max_steps,
                 count_swaps=config.count_swaps, goal_reward=config.goal_reward,
                 stay_reward=config.stay_reward, obstacle_density=config.obstacle_density,
                 map_rows=config.map_rows, scenario=config.scenario, lifelong=config.lifelong,
                 goal_lists=config.goal_lists)


class Episodes:
    """Per (run, episode) results: the score's fields, the end tick and the shortest paths."""

    def __init__(self, runs: int, episodes: int) -> None:
        self.row = np.zeros((runs, episodes, ROW_INTS), dtype=np.int64)
        self.row_f = np.zeros((runs, episodes, ROW_FLOATS))
        self.out = np.zeros((runs, episodes, OUT_FIELDS), dtype=np.int64)

    steps = property(lambda self: self.row[..., ROW_STEPS])
    collisions = property(lambda self: self.row[..., ROW_COLLISIONS])
    arrived = property(lambda self: self.row[..., ROW_ARRIVED])
    goals = property(lambda self: self.row[..., ROW_GOALS])
    agent_steps = property(lambda self: self.row[..., ROW_AGENT_STEPS])
    reward_sum = property(lambda self: self.row_f[..., ROW_REWARD])
    reward_ds = property(lambda self: self.row_f[..., ROW_REWARD_DS])
    reward_ca = property(lambda self: self.row_f[..., ROW_REWARD_CA])
    end_tick = property(lambda self: self.out[..., OUT_END_TICK])
    shortest = property(lambda self: self.out[..., OUT_SHORTEST])
    violations = property(lambda self: self.out[..., OUT_VIOLATIONS])
    on_goal = property(lambda self: self.out[..., OUT_ON_GOAL])
    soc = property(lambda self: self.out[..., OUT_SOC])
    makespan = property(lambda self: self.out[..., OUT_MAKESPAN])

    def swarm_row(self, run: int, episode: int, learners: int) -> dict:
        """One episode of a run of ``learners`` agents as a row of the swarm's ``episodes.csv``
        (its deterministic columns)."""
        costs = (int(self.on_goal[run, episode]), int(self.soc[run, episode]),
                 int(self.makespan[run, episode]))
        return {
            "episode": episode,
            "steps": int(self.steps[run, episode]),
            "collisions": int(self.collisions[run, episode]),
            "missed_intents": 0,
            "reward_sum": float(self.reward_sum[run, episode]),
            "arrived": int(self.arrived[run, episode]),
            "shortest_sum": int(self.shortest[run, episode]),
            "agent_steps": int(self.agent_steps[run, episode]),
            "end_tick": int(self.end_tick[run, episode]),
            **field_columns(*costs, learners),
            **task_columns(int(self.goals[run, episode]), int(self.steps[run, episode])),
        }


class Batch:
    """Many runs of one world, their tables, learner states and buffers, played episode by
    episode (:meth:`play`)."""

    def __init__(self, world: World, runs: list[SwarmConfig], record: bool = False) -> None:
        if not runs:
            raise ValueError("a batch needs at least one run")
        for run in runs:
            check_run(world, run)
        self.world, self.runs, self.record = world, list(runs), record
        self.episode = 0
        w = world
        r, n, learners = len(runs), w.bodies, w.learners
        cells = w.width * w.height
        rows = max(ca_rows(READINGS.get(run.algo, 0), run.known_state) for run in runs)
        params = [learner_params(run) for run in runs]
        self.params = np.array([ints for ints, _ in params], dtype=np.int64)
        self.params_f = np.array([floats for _, floats in params])
        self.options = np.zeros((r, OPT_FIELDS), dtype=np.int64)
        self.options[:, OPT_SHARED] = [run.shared for run in runs]
        self.options[:, OPT_LOOKAHEAD] = [run.lookahead for run in runs]
        self.options[:, OPT_ORACLE] = [run.algo == "oracle" for run in runs]
        self.options[:, OPT_WALLS] = int(w.scripted > 0 and not w.paper)
        self.options[:, OPT_FROZEN] = [run.frozen for run in runs]
        self.options[:, OPT_STEP_ASIDE] = [run.step_aside for run in runs]
        self.options[:, OPT_PIBT] = [run.arbitration == "pibt" for run in runs]
        init = np.array([run.optimistic for run in runs])[:, None, None, None]
        self.q_ds = np.broadcast_to(init, (r, learners, N_STATES, N_ACTIONS)).copy()
        self.q_ca = np.broadcast_to(init, (r, learners, rows, N_ACTIONS)).copy()
        self.state = np.zeros((r, learners, state_size(n)), dtype=np.int64)
        self.state_f = np.zeros((r, learners, LF_FIELDS))
        self.wmap = np.zeros((r, learners, map_size(w.width, w.height)), dtype=np.int64)
        for run_maps in self.wmap:
            for agent_map in run_maps:
                fresh_map(agent_map)
        self.tick = np.zeros(r, dtype=np.int64)
        # Runs of one seed draw the same noise (the same streams, the same draws each episode).
        self.generators = {seed: [stream_rng(seed, AGENT_STREAM, i) for i in range(learners)]
                           for seed in sorted({run.seed for run in runs})}
        self.trace = np.zeros((r, w.max_steps + 1 if record else 1, n, TR_FIELDS), dtype=np.int64)
        self.learns = np.arange(n) < learners
        self._seeds = list(self.generators)
        self._seed_of_run = np.array([self._seeds.index(run.seed) for run in runs])
        self._bodies = Bodies(_ints(r, n), _ints(r, n), _ints(r, n), _ints(r, n), self.learns,
                              np.zeros((r, n), dtype=bool), _ints(r, n))
        self._moves = Moves(_ints(r, n), np.zeros((r, n), dtype=bool), _ints(r, n), _ints(r, n),
                            _ints(r, n), np.zeros((r, n), dtype=bool))
        self._outcome = Outcome(_ints(r, n), _ints(r, n), np.zeros((r, n), dtype=bool),
                                np.zeros((r, n)), np.zeros((r, n)))
        self._scratch = Scratch(_ints(r, cells), np.zeros((r, n), dtype=bool))
        oracle_rows = _ints(r, ORACLE_SCRATCH, cells)
        oracle_rows[:, ORACLE_GOAL_OF] = -1  # no agent's distances worked out yet
        self._oracle = OracleScratch(oracle_rows, _ints(r, n * cells), _ints(r, n * N_ACTIONS))
        self._rec = _ints(r, learners, record_size(n))
        self._rec_f = np.zeros((r, learners, RF_FIELDS))
        self._pending_rec = np.zeros((r, learners), dtype=bool)
        self._values, self._nb = np.zeros((r, VALUES_SIZE)), _ints(r, n, NB_FIELDS)

    def play(self, episodes: int, results: Episodes | None = None, on_episode=None) -> Episodes:
        """Play the next ``episodes`` episodes of every run; ``on_episode(e, batch)`` after each
        (``batch.trace`` then holds episode ``e``'s ticks, if recording)."""
        results = results or Episodes(len(self.runs), self.episode + episodes)
        w, runs = self.world, self.runs
        r = len(runs)
        row = np.zeros((r, ROW_INTS), dtype=np.int64)
        row_f = np.zeros((r, ROW_FLOATS))
        out = np.zeros((r, OUT_FIELDS), dtype=np.int64)
        seeds = len(self.generators)
        seed_actions = np.zeros((seeds, w.learners, w.max_steps), dtype=np.int64)
        seed_ties = np.zeros((seeds, w.learners, w.max_steps, N_ACTIONS))
        rules = EpisodeRules(w.bodies, w.learners, w.width, w.height, w.max_steps, w.count_swaps,
                             w.goal_reward, w.stay_reward, self.record, w.lifelong, w.max_steps)
        per_run = Runs(self.params, self.params_f, self.options, self._seed_of_run, self.tick)
        agents = Learners(self.q_ds, self.q_ca, self.state, self.state_f, self.wmap, self._rec,
                          self._rec_f, self._pending_rec, self._values, self._nb)
        for _ in range(episodes):
            e = self.episode
            scenario = Scenario(*self._scenarios(e))
            for s, generators in enumerate(self.generators.values()):
                for i, rng in enumerate(generators):
                    draw_noise(rng, seed_actions[s, i], seed_ties[s, i])
            run_episode(rules, per_run, agents, scenario, Noise(seed_actions, seed_ties),
                        self._bodies, self._moves, self._outcome, self._scratch, self._oracle,
                        Results(row, row_f, out, self.trace))
            results.row[:, e], results.row_f[:, e], results.out[:, e] = row, row_f, out
            self.episode += 1
            if on_episode is not None:
                on_episode(e, self)
        return results

    def generator(self, run: int, agent: int) -> np.random.Generator:
        """The noise generator of an agent of a run (shared by the runs of its seed)."""
        return self.generators[self.runs[run].seed][agent]

    def tables(self, run: int, agent: int) -> tuple[np.ndarray, np.ndarray]:
        """The Q_DS and Q_CA tables an agent of a run holds (the swarm's one table if shared)."""
        t = 0 if self.runs[run].shared else agent
        rows = ca_rows(READINGS.get(self.runs[run].algo, 0), self.runs[run].known_state)
        return self.q_ds[run, t], self.q_ca[run, t, :rows]

    def load_tables(self, run: int, q_ds: np.ndarray, q_ca: np.ndarray) -> None:
        """Give every agent of a run learned tables: ``q_ds`` and ``q_ca`` hold one table (the
        swarm's, or every agent's alike) or one per agent; agent ``i`` of the run takes table
        ``i`` modulo their number (a policy learned by fewer agents than play it)."""
        q_ds, q_ca = np.asarray(q_ds), np.asarray(q_ca)
        if q_ds.ndim == 2:
            q_ds, q_ca = q_ds[None], q_ca[None]
        rows = self.q_ca.shape[2]
        if q_ds.shape[1:] != self.q_ds.shape[2:] or q_ca.shape[0] != q_ds.shape[0] \
                or q_ca.shape[1] > rows or q_ca.shape[2] != self.q_ca.shape[3]:
            raise ValueError("the tables do not fit the run's learners")
        for agent in range(self.world.learners):
            self.q_ds[run, agent] = q_ds[agent % len(q_ds)]
            self.q_ca[run, agent, :q_ca.shape[1]] = q_ca[agent % len(q_ca)]

    def forget_maps(self) -> None:
        """Every agent of every run forgets the walls it has seen (``learning.known_map``)."""
        for run_maps in self.wmap:
            for agent_map in run_maps:
                fresh_map(agent_map)

    def known_walls(self, run: int, agent: int) -> list[int]:
        """The cells of the walls an agent of a run has seen (``learning.known_map``)."""
        w = self.world
        return known_cells(self.wmap[run, agent], w.width, w.height)

    def actions_taken(self, run: int, agent: int) -> int:
        return int(self.state[run, agent, LS_TAKEN])

    def _scenarios(self, episode: int):
        """Every seed's starts, goals, scripts and the learners' shortest paths of an episode."""
        w = self.world
        starts, goals, scripts, paths, tasks = [], [], [], [], []
        for seed in self._seeds:
            if w.paper:
                paper = paper_episode(seed, episode, w.width, w.height, w.scripted, w.max_steps)
                starts.append(paper.starts)
                goals.append(paper.goal[None, :])
                scripts.append(paper.obstacle_actions)
                paths.append(np.abs(paper.starts[:1] - paper.goal).sum(axis=1))
                tasks.append(np.zeros(2, dtype=np.int64))
            else:
                swarm = swarm_episode(seed, episode, w.width, w.height, w.learners,
                                      w.obstacle_density, w.map_rows, w.scenario)
                walls = layout(seed, w.width, w.height, w.obstacle_density, w.map_rows)[0]
                check_cell_order(walls.tolist())
                starts.append(np.concatenate([swarm.starts, walls]))
                goals.append(swarm.goals)
                scripts.append(np.full((w.max_steps, len(walls)), STAY, dtype=np.int64))
                paths.append(swarm.shortest)
                tasks.append(goal_sequences(seed, episode, w.width, w.height, walls, swarm.goals,
                                            w.max_steps, w.goal_lists).reshape(-1) if w.lifelong
                             else np.zeros(2, dtype=np.int64))
        return (np.stack(starts), np.stack(goals), np.stack(scripts), np.stack(paths),
                np.stack(tasks))


def compiled_simulator() -> bool:
    """Whether the simulator's kernel loads from the on-disk cache (in a second or two) rather than
    compiling (about half a minute on a 2-core VM): :func:`protocol.jit.cached`."""
    return cached(run_episode)


def warm_up(world: World, run: SwarmConfig) -> None:
    """Compile or load the simulator's kernel: one episode of a throwaway batch of ``run``, whose
    arguments have the types of every batch's. A batch played next starts at full speed, so that
    its first episode times like the others."""
    Batch(world, [run]).play(1)


@contextlib.contextmanager
def threads(count: int | None):
    """Play with ``count`` threads inside the block (None: one per core)."""
    import numba

    before = numba.get_num_threads()
    numba.set_num_threads(max(1, min(count or numba.config.NUMBA_NUM_THREADS,
                                     numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(before)


def check_run(world: World, run: SwarmConfig) -> None:
    """Refuse a run the simulator cannot play, with the reason."""
    if run.algo not in READINGS and run.algo != "oracle":
        raise ValueError(f"unknown algorithm {run.algo!r}")
    if run.algo == "oracle" and world.paper:
        raise ValueError("the oracle plans swarms of learners, not scripted obstacles")
    if run.obstacle_density != world.obstacle_density:
        raise ValueError("every run of a batch needs the world's obstacle density")
    if (run.lifelong, run.goal_lists) != (world.lifelong, world.goal_lists):
        raise ValueError("every run of a batch needs the world's tasks (one-shot or lifelong)")
    if (run.map_rows, run.scenario) != (world.map_rows, world.scenario):
        raise ValueError("every run of a batch needs the world's map and scenario")


def _ints(*shape: int) -> np.ndarray:
    return np.zeros(shape, dtype=np.int64)
