"""The paper's experiment (Section 4), batched: one learner among scripted obstacles, many runs at once.

Every run is one learner (QL or nnQL, random step k, seed) among ``n_obstacles`` scripted obstacles
whose starts and every action come from :mod:`world.scenario`; the obstacles announce their
pre-generated next action, which only nnQL reads. All runs advance episode by episode in lockstep
through the same array code (``agent.learning``, ``world.rules``); a run whose learner has arrived
sits out the rest of that episode, and once most of the batch has finished, the finished runs leave
the arrays (``COMPACT_BELOW``), so late steps cost what the runs still going cost. Each run gives
exactly what it would give alone, so a batch may also be split over worker processes (``workers``)
without changing a single number.
"""

import contextlib
import copy
import multiprocessing
import queue
import signal
import threading
from dataclasses import dataclass, field, fields
from typing import Callable

import numpy as np

from agent.learning import EpisodeNoise, Hyper, Learners, View
from protocol.actions import STAY, VIEW_RADIUS, intended_cell
from protocol.seeding import AGENT_STREAM, stream_rng
from world.rules import GOAL_REWARD, arbitrate, collision_reward, destination_reward, shortest_steps
from world.scenario import paper_episode

ALGOS = ("ql", "nnql")
LEARNER_ID = 0


@dataclass(frozen=True)
class PaperSettings:
    """The paper's settings are the defaults; grid and obstacle count are calibrated (README)."""

    episodes: int = 500
    max_steps: int = 100
    width: int = 11
    height: int = 11
    n_obstacles: int = 3
    count_swaps: bool = False
    goal_reward: float = GOAL_REWARD
    hyper: Hyper = field(default_factory=Hyper)


@dataclass(frozen=True)
class RunSpec:
    """One independent run of the experiment."""

    algo: str
    random_step: int
    seed: int


@dataclass
class EpisodeMetrics:
    """Per (run, episode) results, arrays of shape ``(runs, episodes)``."""

    steps: np.ndarray
    collisions: np.ndarray
    reward_ds: np.ndarray
    reward_ca: np.ndarray
    shortest: np.ndarray
    arrived: np.ndarray

    @staticmethod
    def empty(runs: int, episodes: int) -> "EpisodeMetrics":
        return EpisodeMetrics(
            steps=np.zeros((runs, episodes), dtype=np.int64),
            collisions=np.zeros((runs, episodes), dtype=np.int64),
            reward_ds=np.zeros((runs, episodes)),
            reward_ca=np.zeros((runs, episodes)),
            shortest=np.zeros((runs, episodes), dtype=np.int64),
            arrived=np.zeros((runs, episodes), dtype=bool),
        )

    def put_rows(self, rows: np.ndarray | list[int], part: "EpisodeMetrics") -> None:
        """Copy ``part``'s runs into the given rows of this one."""
        for name in (f.name for f in fields(self)):
            getattr(self, name)[rows] = getattr(part, name)


def run_batch(
    specs: list[RunSpec],
    settings: PaperSettings = PaperSettings(),
    on_episode: Callable[[int], None] | None = None,
    workers: int = 1,
) -> EpisodeMetrics:
    """Run every spec through every episode; ``on_episode(e)`` is called after each episode.

    With ``workers > 1`` the specs are shared out over that many processes; ``on_episode(e)`` is
    then called once every worker has finished episode ``e``. The results are the same either way.
    """
    for spec in specs:
        if spec.algo not in ALGOS:
            raise ValueError(f"unknown algorithm {spec.algo!r}; choose from {', '.join(ALGOS)}")
    workers = max(1, min(int(workers), len(specs)))
    if workers == 1:
        return _run_in_process(specs, settings, on_episode)
    return _run_in_workers(specs, settings, on_episode, workers)


def _run_in_process(
    specs: list[RunSpec], s: PaperSettings, on_episode: Callable[[int], None] | None
) -> EpisodeMetrics:
    runs = len(specs)
    learners = Learners(
        random_step=np.array([spec.random_step for spec in specs]),
        use_intents=np.array([spec.algo == "nnql" for spec in specs]),
        n_neighbours=s.n_obstacles,
        hyper=s.hyper,
    )
    rngs = [stream_rng(spec.seed, AGENT_STREAM, LEARNER_ID) for spec in specs]
    seeds = sorted({spec.seed for spec in specs})
    seed_row = np.array([seeds.index(spec.seed) for spec in specs], dtype=np.int64)
    metrics = EpisodeMetrics.empty(runs, s.episodes)

    for episode in range(s.episodes):
        scenarios = [paper_episode(seed, episode, s.width, s.height, s.n_obstacles, s.max_steps)
                     for seed in seeds]
        noise = [EpisodeNoise.draw(rng, s.max_steps) for rng in rngs]
        batch = _EpisodeBatch(
            rows=np.arange(runs),
            learners=learners,
            positions=np.stack([sc.starts for sc in scenarios])[seed_row],
            goal=np.stack([sc.goal for sc in scenarios])[seed_row],
            script=np.stack([sc.obstacle_actions for sc in scenarios])[seed_row],
            random_actions=np.stack([n.random_actions for n in noise]),
            tie_breakers=np.stack([n.tie_breakers for n in noise]),
        )
        metrics.shortest[:, episode] = shortest_steps(batch.positions[:, LEARNER_ID], batch.goal)
        for t in range(s.max_steps):
            batch.step(t, s)
            if not batch.running.any():
                break
            if batch.running.sum() <= COMPACT_BELOW * batch.rows.size:
                batch = batch.compact(learners, metrics, episode)
        batch.close(learners, metrics, episode)
        if on_episode is not None:
            on_episode(episode)
    return metrics


COMPACT_BELOW = 0.5
"""Once no more than this fraction of an episode's working batch still runs, the finished runs
leave the batch, so the per-step array work follows the runs still going. 0 never compacts."""


class _EpisodeBatch:
    """The runs still taking part in one episode: their learners, world state and sums so far.

    ``rows`` are the runs' indices in the whole batch; every other array is indexed by position in
    ``rows``. ``learners`` is the whole batch's :class:`Learners` until the first compaction, then
    a copy of just these runs' learners, written back on the next compaction or at the end.
    """

    def __init__(self, rows, learners, positions, goal, script, random_actions, tie_breakers):
        n = rows.size
        self.rows, self.learners = rows, learners
        self.positions, self.goal, self.script = positions, goal, script
        self.random_actions, self.tie_breakers = random_actions, tie_breakers
        self.running = np.ones(n, dtype=bool)
        self.steps = np.zeros(n, dtype=np.int64)
        self.collisions = np.zeros(n, dtype=np.int64)
        self.reward_ds = np.zeros(n)
        self.reward_ca = np.zeros(n)
        self.arrived = np.zeros(n, dtype=bool)

    def step(self, t: int, s: PaperSettings) -> None:
        """One step of every run: decide, arbitrate, reward, learn, and let arrived runs leave."""
        running, positions, goal, learners = self.running, self.positions, self.goal, self.learners
        script = self.script[:, t]
        known = np.ones(script.shape, dtype=bool)
        obstacles_next = intended_cell(positions[:, 1:], script, s.width, s.height)
        view = _learner_view(positions, goal, obstacles_next, known)
        action = learners.decide(view, running, self.random_actions[:, t], self.tie_breakers[:, t])
        actions = np.concatenate([np.where(running, action, STAY)[:, None], script], axis=1)
        moved, collided = arbitrate(positions, actions, s.width, s.height, s.count_swaps)
        own_after = moved[:, LEARNER_ID]
        r_ds = destination_reward(positions[:, LEARNER_ID], own_after, goal, s.goal_reward)
        learner_collided = collided[:, LEARNER_ID]
        r_ca = collision_reward(learner_collided)
        arrived = (own_after[:, 0] == goal[:, 0]) & (own_after[:, 1] == goal[:, 1]) & running
        learners.record(r_ds, r_ca, arrived)

        self.steps += running
        self.collisions += learner_collided & running
        self.reward_ds += np.where(running, r_ds, 0.0)
        self.reward_ca += np.where(running, r_ca, 0.0)
        self.arrived |= arrived
        self.positions = np.where(running[:, None, None], moved, positions)

        leaving = running if t == s.max_steps - 1 else arrived
        if leaving.any():
            # s' of a leaving learner is read without intents, so nobody's next cell matters.
            learners.finish(leaving, _learner_view(self.positions, goal, self.positions[:, 1:], known))
        self.running = running & ~arrived

    def compact(self, everyone: Learners, metrics: EpisodeMetrics, episode: int) -> "_EpisodeBatch":
        """A batch of just the runs still going; the finished ones' results go home."""
        keep, done = np.flatnonzero(self.running), np.flatnonzero(~self.running)
        self._store(done, everyone, metrics, episode)
        part = _EpisodeBatch(
            self.rows[keep], _take_learners(self.learners, keep), self.positions[keep],
            self.goal[keep], self.script[keep], self.random_actions[keep], self.tie_breakers[keep],
        )
        for name in ("steps", "collisions", "reward_ds", "reward_ca", "arrived"):
            setattr(part, name, getattr(self, name)[keep])
        return part

    def close(self, everyone: Learners, metrics: EpisodeMetrics, episode: int) -> None:
        """Store every run's results and learners at the episode's end."""
        self._store(np.arange(self.rows.size), everyone, metrics, episode)

    def _store(self, at: np.ndarray, everyone: Learners, metrics: EpisodeMetrics, episode: int):
        rows = self.rows[at]
        if self.learners is not everyone:
            _put_learners(everyone, rows, _take_learners(self.learners, at))
        metrics.steps[rows, episode] = self.steps[at]
        metrics.collisions[rows, episode] = self.collisions[at]
        metrics.reward_ds[rows, episode] = self.reward_ds[at]
        metrics.reward_ca[rows, episode] = self.reward_ca[at]
        metrics.arrived[rows, episode] = self.arrived[at]


def _per_learner_arrays(learners: Learners) -> dict[str, np.ndarray]:
    """Every array of a :class:`Learners` that holds one entry per learner (leading batch axis).

    ``agent.learning`` keeps a batch of independent learners as arrays over the batch, so a subset
    of learners is those arrays' rows; the other attributes (the hyper-parameters) are shared.
    """
    return {
        name: value for name, value in vars(learners).items()
        if isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == learners.batch
    }


def _take_learners(learners: Learners, rows: np.ndarray) -> Learners:
    """A copy of the learners ``rows``, pending updates included."""
    part = copy.copy(learners)
    for name, value in _per_learner_arrays(learners).items():
        setattr(part, name, value[rows])
    return part


def _put_learners(learners: Learners, rows: np.ndarray, part: Learners) -> None:
    """Write ``part`` (a :func:`_take_learners` copy, since advanced) back into ``rows``."""
    for name, value in _per_learner_arrays(part).items():
        getattr(learners, name)[rows] = value


def _learner_view(
    positions: np.ndarray, goal: np.ndarray, obstacles_next: np.ndarray, known: np.ndarray
) -> View:
    """The learner's view: obstacles' cells, their announced next cells, who is in view."""
    own = positions[:, LEARNER_ID]
    obstacles = positions[:, LEARNER_ID + 1:]
    offset = np.abs(obstacles - own[:, None, :])
    return View(
        own=own,
        goal=goal,
        nb_cells=obstacles,
        nb_next=obstacles_next,
        nb_known=known,
        nb_visible=(offset[..., 0] <= VIEW_RADIUS) & (offset[..., 1] <= VIEW_RADIUS),
    )


class _Orphaned(Exception):
    """The parent of a worker is gone: nobody will read its results."""


def _worker(
    index: int, specs: list[RunSpec], settings: PaperSettings, outbox: multiprocessing.Queue
) -> None:
    """A worker process: run its share of specs, report each episode, then send the metrics."""
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C and stops us
    parent = multiprocessing.parent_process()

    def report(episode: int) -> None:
        if parent is not None and not parent.is_alive():
            raise _Orphaned
        outbox.put(("episode", index, episode))

    try:
        metrics = _run_in_process(specs, settings, report)
        outbox.put(("done", index, metrics))
    except _Orphaned:
        outbox.cancel_join_thread()
    except Exception as error:  # handed to the parent, which raises it
        outbox.put(("error", index, repr(error)))


@contextlib.contextmanager
def _sigint_ignored():
    """Ignore SIGINT inside the block (when this is the main thread, where handlers can be set)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _run_in_workers(
    specs: list[RunSpec],
    settings: PaperSettings,
    on_episode: Callable[[int], None] | None,
    workers: int,
) -> EpisodeMetrics:
    # Interleaved shares, so every worker gets a similar mix of slow (small k) and fast runs.
    shares = [list(range(i, len(specs), workers)) for i in range(workers)]
    context = multiprocessing.get_context("spawn")
    outbox = context.Queue()
    processes = [
        context.Process(
            target=_worker, args=(i, [specs[r] for r in share], settings, outbox), daemon=True
        )
        for i, share in enumerate(shares)
    ]
    metrics = EpisodeMetrics.empty(len(specs), settings.episodes)
    episodes_done = [0] * workers
    reported = 0
    finished: set[int] = set()
    try:
        with _sigint_ignored():  # children inherit it, so Ctrl-C reaches only this process
            for process in processes:
                process.start()
        while len(finished) < workers:
            try:
                kind, index, payload = outbox.get(timeout=1.0)
            except queue.Empty:
                for i, process in enumerate(processes):
                    if i not in finished and process.exitcode is not None:
                        raise RuntimeError(
                            f"paper worker {i} exited early with code {process.exitcode}"
                        )
                continue
            if kind == "error":
                raise RuntimeError(f"worker {index} failed: {payload}")
            if kind == "done":
                metrics.put_rows(shares[index], payload)
                finished.add(index)
                continue
            episodes_done[index] = payload + 1
            while reported < min(episodes_done):
                if on_episode is not None:
                    on_episode(reported)
                reported += 1
    finally:
        for process in processes:
            if process.pid is None:
                continue
            if process.is_alive():
                process.terminate()
            process.join()
    return metrics
