"""The paper's experiment (Section 4), batched: one learner among scripted obstacles, many runs at once.

Every run is one learner (QL or nnQL, random step k, seed) among ``n_obstacles`` scripted obstacles
whose starts and every action come from :mod:`world.scenario`; the obstacles announce their
pre-generated next action, which only nnQL reads. All runs advance episode by episode in lockstep
through the same array code (``agent.learning``, ``world.rules``); a run whose learner has arrived
sits out the rest of that episode. Each run gives exactly what it would give alone.
"""

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from agent.learning import EpisodeNoise, Hyper, Learners, View
from protocol.actions import STAY, in_view, intended_cell
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


def run_batch(
    specs: list[RunSpec],
    settings: PaperSettings = PaperSettings(),
    on_episode: Callable[[int], None] | None = None,
) -> EpisodeMetrics:
    """Run every spec through every episode; ``on_episode(e)`` is called after each episode."""
    for spec in specs:
        if spec.algo not in ALGOS:
            raise ValueError(f"unknown algorithm {spec.algo!r}; choose from {', '.join(ALGOS)}")
    runs = len(specs)
    s = settings
    learners = Learners(
        random_step=np.array([spec.random_step for spec in specs]),
        use_intents=np.array([spec.algo == "nnql" for spec in specs]),
        n_neighbours=s.n_obstacles,
        hyper=s.hyper,
    )
    rngs = [stream_rng(spec.seed, AGENT_STREAM, LEARNER_ID) for spec in specs]
    seeds = sorted({spec.seed for spec in specs})
    seed_row = np.array([seeds.index(spec.seed) for spec in specs])
    metrics = EpisodeMetrics.empty(runs, s.episodes)
    rows = np.arange(runs)

    for episode in range(s.episodes):
        scenarios = [paper_episode(seed, episode, s.width, s.height, s.n_obstacles, s.max_steps)
                     for seed in seeds]
        positions = np.stack([scenarios[i].starts for i in seed_row])
        goal = np.stack([scenarios[i].goal for i in seed_row])
        script = np.stack([scenarios[i].obstacle_actions for i in seed_row])
        noise = [EpisodeNoise.draw(rng, s.max_steps) for rng in rngs]
        random_actions = np.stack([n.random_actions for n in noise])
        tie_breakers = np.stack([n.tie_breakers for n in noise])
        metrics.shortest[:, episode] = shortest_steps(positions[:, LEARNER_ID], goal)
        running = np.ones(runs, dtype=bool)

        for t in range(s.max_steps):
            view = _learner_view(positions, goal, script[:, t], s)
            action = learners.decide(view, running, random_actions[:, t], tie_breakers[:, t])
            actions = np.concatenate(
                [np.where(running, action, STAY)[:, None], script[:, t]], axis=1
            )
            moved, collided = arbitrate(positions, actions, s.width, s.height, s.count_swaps)
            own_before, own_after = positions[:, LEARNER_ID], moved[:, LEARNER_ID]
            r_ds = destination_reward(own_before, own_after, goal, s.goal_reward)
            r_ca = collision_reward(collided[:, LEARNER_ID])
            arrived = np.all(own_after == goal, axis=-1) & running
            learners.record(r_ds, r_ca, arrived)

            metrics.steps[running, episode] += 1
            metrics.collisions[running, episode] += collided[running, LEARNER_ID]
            metrics.reward_ds[running, episode] += r_ds[running]
            metrics.reward_ca[running, episode] += r_ca[running]
            metrics.arrived[rows[arrived], episode] = True
            positions = np.where(running[:, None, None], moved, positions)

            leaving = arrived | (running & (t == s.max_steps - 1))
            if leaving.any():
                next_script = script[:, min(t + 1, s.max_steps - 1)]
                learners.finish(leaving, _learner_view(positions, goal, next_script, s))
            running &= ~arrived
            if not running.any():
                break
        if on_episode is not None:
            on_episode(episode)
    return metrics


def _learner_view(
    positions: np.ndarray, goal: np.ndarray, obstacle_actions: np.ndarray, s: PaperSettings
) -> View:
    """The learner's view: obstacles' cells, their announced next cells, who is in view."""
    own = positions[:, LEARNER_ID]
    obstacles = positions[:, LEARNER_ID + 1:]
    return View(
        own=own,
        goal=goal,
        nb_cells=obstacles,
        nb_next=intended_cell(obstacles, obstacle_actions, s.width, s.height),
        nb_known=np.ones(obstacles.shape[:2], dtype=bool),
        nb_visible=in_view(obstacles - own[:, None, :]),
    )
