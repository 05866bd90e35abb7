"""The swarm simulator: the oracle's guarantees, determinism, a batch against each run alone, the
invariants, and the kernel run uncompiled against the kernel compiled."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, Episodes, swarm_world

ROOT = Path(__file__).resolve().parent.parent


def configs(preset: str, seeds, **fields) -> list[SwarmConfig]:
    return [SwarmConfig(seed=seed, **{**PRESETS[preset], **fields}) for seed in seeds]


def play(runs: list[SwarmConfig], episodes: int):
    return Batch(swarm_world(runs[0]), runs).play(episodes)


@pytest.mark.parametrize("agents, grid", [(8, 11), (16, 11)])
def test_the_oracle_brings_everyone_home_without_a_collision(agents, grid):
    runs = configs("oracle", range(6), n_agents=agents, width=grid, height=grid)
    episodes = play(runs, 15)
    assert (episodes.arrived == agents).all(), "every agent arrives in every episode"
    assert not episodes.collisions.any() and not episodes.violations.any()
    assert (episodes.agent_steps >= episodes.shortest).all()


def test_in_a_crowd_the_oracle_never_collides_though_arrived_agents_may_wall_some_in():
    """30 agents on 12 x 12: arrived agents stay on their goals, and now and then they
    close the last way to another's goal; PIBT still never plans a collision."""
    episodes = play(configs("oracle", range(6), n_agents=30, width=12, height=12), 15)
    assert not episodes.collisions.any() and not episodes.violations.any()
    assert episodes.arrived.mean() / 30 > 0.98


def test_a_batch_of_swarms_gives_what_each_gives_alone():
    runs = [*configs("shield-nnql", (1, 2)), *configs("nnql", (1,)), *configs("daql", (3,)),
            *configs("best-nnql", (2,)), *configs("nnql-n2", (4,))]
    together = play(runs, 6)
    for row, run in enumerate(runs):
        alone = play([run], 6)
        assert np.array_equal(together.row[row], alone.row[0]), run.algo
        assert np.array_equal(together.row_f[row], alone.row_f[0]), run.algo
        assert np.array_equal(together.out[row], alone.out[0]), run.algo


def test_the_same_runs_twice_are_the_same_and_seeds_differ():
    first, again = play(configs("best-nnql", (5, 6)), 8), play(configs("best-nnql", (5, 6)), 8)
    assert np.array_equal(first.row, again.row) and np.array_equal(first.row_f, again.row_f)
    assert not np.array_equal(first.row[0], first.row[1])


@pytest.mark.parametrize("preset", ["nnql", "shield-nnql", "daql"])
def test_no_tick_breaks_an_invariant(preset):
    runs = configs(preset, range(3), n_agents=20, width=9, height=9)
    assert not play(runs, 10).violations.any()


def test_the_shield_keeps_learning_agents_almost_free_of_collisions():
    shielded, paper = play(configs("shield-nnql", range(3)), 60), play(configs("nnql", range(3)), 60)
    assert shielded.collisions.sum() * 20 < paper.collisions.sum()


def test_the_escape_shield_leaves_no_collision_in_a_crowd_among_walls():
    """32 agents learning on 19 x 19 with 20 % walls: the default preset's escape shield pushes
    only an agent that surely has a cell to move on to, so no move collides; without it,
    agents pushed into cells of agents that could not leave do collide."""
    crowd = {"n_agents": 32, "width": 19, "height": 19, "obstacle_density": 0.2}
    assert PRESETS["path-nnql"]["escape_shield"]
    escaped = play(configs("path-nnql", range(3), **crowd), 30)
    pushed = play(configs("path-nnql", range(3), escape_shield=False, **crowd), 30)
    assert not escaped.collisions.any() and not escaped.violations.any()
    assert pushed.collisions.sum() > 0
    assert escaped.arrived.mean() > 0.9 * pushed.arrived.mean()


PLAIN_RUN = """
import json, sys
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, swarm_world
runs = [SwarmConfig(seed=s, n_agents=6, max_steps=30, **PRESETS[p])
        for p, s in (("shield-nnql", 1), ("best-nnql", 2), ("daql", 3), ("nnql-n2", 4))]
e = Batch(swarm_world(runs[0]), runs).play(3)
print(json.dumps([e.row.tolist(), e.row_f.tolist(), e.out.tolist()]))
"""


def test_the_kernel_uncompiled_plays_exactly_what_it_plays_compiled():
    """The one source, both ways: plain Python (as the swarm's processes run it) and numba."""
    results = []
    for mode in ("python", "compiled"):
        env = {**os.environ, "NNQL_KERNEL": mode}
        done = subprocess.run([sys.executable, "-c", PLAIN_RUN], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, done.stderr
        results.append(json.loads(done.stdout))
    assert results[0] == results[1]


@pytest.mark.parametrize("preset", ["path-nnql", "oracle"])
def test_under_step_aside_agents_make_way_and_the_score_counts_each_last_arrival(preset):
    """Arrived agents leave their goals to make way and come back; the row's arrivals are the
    agents on their goals at the end, and its learner-steps each one's last arrival step (the
    steps played for one not home), as the recorded ticks show."""
    from nnql_swarm.sim.episode import TR_ARRIVED

    config = SwarmConfig(n_agents=16, episodes=40, obstacle_density=0.2, seed=3,
                         on_target="step-aside", **PRESETS[preset])
    left = 0

    def check(e, batch):
        nonlocal left
        steps = int(episodes.steps[0, e])
        on_goal = batch.trace[0, :steps + 1, :config.n_agents, TR_ARRIVED]
        assert episodes.arrived[0, e] == on_goal[steps].sum()
        expected = 0
        for i in range(config.n_agents):
            arrivals = [t for t in range(1, steps + 1) if on_goal[t, i] and not on_goal[t - 1, i]]
            left += sum(1 for t in range(1, steps + 1) if on_goal[t - 1, i] and not on_goal[t, i])
            expected += arrivals[-1] if on_goal[steps, i] else steps
        assert episodes.agent_steps[0, e] == expected

    episodes = Episodes(1, config.episodes)
    Batch(swarm_world(config), [config], record=True).play(config.episodes, results=episodes,
                                                           on_episode=check)
    assert not episodes.violations.any()
    assert left > 0, "no agent ever made way"
