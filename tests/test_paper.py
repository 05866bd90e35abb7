"""The paper's runner: determinism, threads, per-episode bookkeeping, learning, Table 1's
numbers pinned."""

import numpy as np
import pytest

from nnql_swarm.experiment.paper import EpisodeMetrics, PaperSettings, RunSpec, run_batch
from nnql_swarm.world.rules import CA_REWARD

SHORT = PaperSettings(episodes=8, max_steps=40)
SPECS = [RunSpec(algo, k, seed) for algo in ("ql", "nnql") for k in (1, 3) for seed in (0, 1)]
METRICS = ("steps", "collisions", "reward_ds", "reward_ca", "shortest", "arrived")


def assert_same(a: EpisodeMetrics, b: EpisodeMetrics) -> None:
    for name in METRICS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_same_specs_same_metrics():
    assert_same(run_batch(SPECS, SHORT), run_batch(SPECS, SHORT))


def test_threads_give_the_same_metrics_and_report_every_episode():
    seen = []
    split = run_batch(SPECS, SHORT, on_episode=seen.append, workers=2)
    assert seen == list(range(SHORT.episodes))
    assert_same(split, run_batch(SPECS, SHORT))


def test_on_episode_in_process():
    seen = []
    run_batch(SPECS[:1], SHORT, on_episode=seen.append, workers=1)
    assert seen == list(range(SHORT.episodes))


def test_bookkeeping_is_consistent():
    m = run_batch(SPECS, SHORT)
    assert np.all((m.steps >= 1) & (m.steps <= SHORT.max_steps))
    assert np.all(m.steps[m.arrived] >= m.shortest[m.arrived])
    assert np.all(m.steps[~m.arrived] == SHORT.max_steps)
    assert np.all(m.collisions <= m.steps)
    assert np.array_equal(m.reward_ca, CA_REWARD * (m.steps - m.collisions))
    assert np.all(m.shortest >= 1)


def test_both_algorithms_see_the_same_scenarios_and_seeds_differ():
    m = run_batch(SPECS, SHORT)
    by_spec = {spec: row for row, spec in enumerate(SPECS)}
    assert np.array_equal(m.shortest[by_spec[RunSpec("ql", 3, 0)]], m.shortest[by_spec[RunSpec("nnql", 1, 0)]])
    assert not np.array_equal(m.shortest[by_spec[RunSpec("ql", 3, 0)]], m.shortest[by_spec[RunSpec("ql", 3, 1)]])


def test_learning_shortens_episodes():
    settings = PaperSettings(episodes=150)
    m = run_batch([RunSpec("nnql", 10, seed) for seed in range(3)], settings)
    assert m.steps[:, -30:].mean() < 0.65 * m.steps[:, :30].mean()


def test_unknown_algorithm_is_refused():
    with pytest.raises(ValueError, match="unknown algorithm"):
        run_batch([RunSpec("sarsa", 2, 0)], SHORT)


def test_table_1_runs_give_the_numbers_of_the_batch_code_before_the_kernel():
    """Total collisions of a run (k = 2, 5, 10; seeds 0-2; 60 episodes), as the numpy batch
    runner of ``agent.learning`` gave them: the kernel changed no number of Table 1."""
    settings = PaperSettings(episodes=60)
    specs = [RunSpec(algo, k, seed) for algo in ("ql", "nnql") for k in (2, 5, 10) for seed in range(3)]
    totals = run_batch(specs, settings).collisions.sum(axis=1).tolist()
    assert totals == BEFORE_THE_KERNEL


BEFORE_THE_KERNEL = [49, 70, 71, 43, 49, 57, 56, 66, 82, 22, 37, 35, 29, 20, 32, 43, 15, 57]
