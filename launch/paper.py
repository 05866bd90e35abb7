"""The paper's experiment (Section 4), batched: one learner among scripted obstacles, many runs at once.

Every run is one learner (QL or nnQL, random step k, seed) among ``n_obstacles`` scripted obstacles
whose starts and every action come from :mod:`world.scenario`; the obstacles announce their
pre-generated next action, which only nnQL reads. All runs advance episode by episode in lockstep
through the same array code (``agent.learning``, ``world.rules``); a run whose learner has arrived
sits out the rest of that episode. Each run gives exactly what it would give alone, so a batch may
also be split over worker processes (``workers``) without changing a single number.
"""

import contextlib
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
    everyone_known = np.ones((runs, s.n_obstacles), dtype=bool)
    actions = np.empty((runs, 1 + s.n_obstacles), dtype=np.int64)

    for episode in range(s.episodes):
        scenarios = [paper_episode(seed, episode, s.width, s.height, s.n_obstacles, s.max_steps)
                     for seed in seeds]
        positions = np.stack([sc.starts for sc in scenarios])[seed_row]
        goal = np.stack([sc.goal for sc in scenarios])[seed_row]
        script = np.stack([sc.obstacle_actions for sc in scenarios])[seed_row]
        noise = [EpisodeNoise.draw(rng, s.max_steps) for rng in rngs]
        random_actions = np.stack([n.random_actions for n in noise])
        tie_breakers = np.stack([n.tie_breakers for n in noise])
        metrics.shortest[:, episode] = shortest_steps(positions[:, LEARNER_ID], goal)
        running = np.ones(runs, dtype=bool)
        steps = np.zeros(runs, dtype=np.int64)
        collisions = np.zeros(runs, dtype=np.int64)
        reward_ds = np.zeros(runs)
        reward_ca = np.zeros(runs)
        arrived_ever = np.zeros(runs, dtype=bool)

        for t in range(s.max_steps):
            obstacles_next = intended_cell(positions[:, 1:], script[:, t], s.width, s.height)
            view = _learner_view(positions, goal, obstacles_next, everyone_known)
            action = learners.decide(view, running, random_actions[:, t], tie_breakers[:, t])
            actions[:, LEARNER_ID] = np.where(running, action, STAY)
            actions[:, 1:] = script[:, t]
            moved, collided = arbitrate(positions, actions, s.width, s.height, s.count_swaps)
            own_after = moved[:, LEARNER_ID]
            r_ds = destination_reward(positions[:, LEARNER_ID], own_after, goal, s.goal_reward)
            learner_collided = collided[:, LEARNER_ID]
            r_ca = collision_reward(learner_collided)
            arrived = (own_after[:, 0] == goal[:, 0]) & (own_after[:, 1] == goal[:, 1]) & running
            learners.record(r_ds, r_ca, arrived)

            steps += running
            collisions += learner_collided & running
            reward_ds += np.where(running, r_ds, 0.0)
            reward_ca += np.where(running, r_ca, 0.0)
            arrived_ever |= arrived
            positions = np.where(running[:, None, None], moved, positions)

            last_step = t == s.max_steps - 1
            leaving = running if last_step else arrived
            if leaving.any():
                # s' of a leaving learner is read without intents, so nobody's next cell matters.
                last_view = _learner_view(positions, goal, positions[:, 1:], everyone_known)
                learners.finish(leaving, last_view)
            running = running & ~arrived
            if not running.any():
                break

        metrics.steps[:, episode] = steps
        metrics.collisions[:, episode] = collisions
        metrics.reward_ds[:, episode] = reward_ds
        metrics.reward_ca[:, episode] = reward_ca
        metrics.arrived[:, episode] = arrived_ever
        if on_episode is not None:
            on_episode(episode)
    return metrics


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
