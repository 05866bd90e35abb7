"""The paper's experiment (Section 4) on the swarm simulator: one learner among scripted obstacles.

Every run is one learner (QL or nnQL, random step k, seed) among ``n_obstacles`` scripted obstacles
whose starts and every action come from :mod:`world.scenario`; the obstacles announce their
pre-generated next action, which only nnQL reads. The runs are played by ``sim.episode`` (the same
learner and rules as the swarm), all at once, episode by episode, spread over the cores
(``workers`` threads); each run gives exactly what it would give alone.
"""

from dataclasses import dataclass, fields
from typing import Callable

import numpy as np

from nnql_swarm.protocol.config import PAPER, SwarmConfig
from nnql_swarm.sim.runs import Batch, World, threads
from nnql_swarm.world.rules import GOAL_REWARD

ALGOS = ("ql", "nnql")


@dataclass(frozen=True)
class PaperSettings:
    """The paper's settings are the defaults; grid and obstacle count are calibrated
    (docs/paper.md)."""

    episodes: int = 500
    max_steps: int = 100
    width: int = 11
    height: int = 11
    n_obstacles: int = 3
    count_swaps: bool = False
    goal_reward: float = GOAL_REWARD
    alpha: float = 0.9
    gamma: float = 0.6
    beta: float = 0.5


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

    def names(self) -> list[str]:
        return [f.name for f in fields(self)]


def paper_world(s: PaperSettings) -> World:
    """The simulator's world of the paper's experiment: one learner among scripted obstacles."""
    return World(bodies=1 + s.n_obstacles, learners=1, width=s.width, height=s.height,
                 max_steps=s.max_steps, count_swaps=s.count_swaps, goal_reward=s.goal_reward)


def paper_run(spec: RunSpec, s: PaperSettings) -> SwarmConfig:
    """The learner's options of one run of the paper's experiment."""
    return SwarmConfig(n_agents=1, seed=spec.seed, random_step=spec.random_step,
                       **{**PAPER, "algo": spec.algo, "alpha": s.alpha, "beta": s.beta},
                       gamma=s.gamma)


def run_batch(
    specs: list[RunSpec],
    settings: PaperSettings = PaperSettings(),
    on_episode: Callable[[int], None] | None = None,
    workers: int | None = None,
) -> EpisodeMetrics:
    """Run every spec through every episode; ``on_episode(e)`` is called after each episode.
    ``workers``: threads to spread the runs over (default: every core); the results are the
    same for any number."""
    for spec in specs:
        if spec.algo not in ALGOS:
            raise ValueError(f"unknown algorithm {spec.algo!r}; choose from {', '.join(ALGOS)}")
    runs = [paper_run(spec, settings) for spec in specs]
    callback = None if on_episode is None else (lambda episode, _batch: on_episode(episode))
    with threads(workers):
        played = Batch(paper_world(settings), runs).play(settings.episodes, on_episode=callback)
    return EpisodeMetrics(steps=played.steps, collisions=played.collisions,
                          reward_ds=played.reward_ds, reward_ca=played.reward_ca,
                          shortest=played.shortest, arrived=played.arrived > 0)
