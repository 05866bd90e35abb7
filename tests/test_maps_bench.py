"""The field's metrics (CSR, ISR, SoC, makespan) on hand-made episodes, and the maps benchmark:
frozen play writes no table, the command line writes its table and curves, refuses bad values
and keeps what it wrote when interrupted."""

import csv
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from nnql_swarm.experiment.maps_benchmark import (
    EPISODE_COLUMNS, MapsBenchmark, Recorder, map_spec, play_frozen, run_config, table_rows,
    train,
)
from nnql_swarm.protocol.actions import DOWN, RIGHT, STAY
from nnql_swarm.world.terrain import generated
from nnql_swarm.world.rules import (
    FIELD_COLUMNS, GOAL_REWARD, ROW_FLOATS, ROW_INTS, STAY_REWARD, Bodies, Outcome, Rules, Scratch,
    Score, field_columns, field_costs, world_step,
)
from tests.swarm_helpers import EXPERIMENT, ROOT, experiment, read_csv

TINY = ["maps", "--seeds", "2", "--train-maps", "2", "--train-episodes", "5", "--test-maps", "1",
        "--instances", "2", "--agents", "4,6", "--scratch-episodes", "10", "--scratch-agents", "4"]


def ints(values):
    return np.array(values, dtype=np.int64)


def play(cells, goals, moves, steps):
    """A hand-made episode of ``steps`` steps on an open 5 x 5 grid: ``moves[t]`` the actions of
    step ``t`` (STAY after the list ends); returns the field's columns."""
    n = len(cells)
    x, y = ints([c[0] for c in cells]), ints([c[1] for c in cells])
    gx, gy = ints([g[0] for g in goals]), ints([g[1] for g in goals])
    arrived, arrival = np.zeros(n, bool), np.zeros(n, np.int64)
    row, row_f = np.zeros(ROW_INTS, np.int64), np.zeros(ROW_FLOATS)
    for t in range(steps):
        actions = ints(moves[t] if t < len(moves) else [STAY] * n)
        rules = Rules(n, 5, 5, True, False, GOAL_REWARD, STAY_REWARD)
        bodies = Bodies(x, y, gx, gy, np.ones(n, bool), arrived, arrival)
        outcome = Outcome(np.zeros(n, np.int64), np.zeros(n, np.int64), np.zeros(n, bool),
                          np.zeros(n), np.zeros(n))
        scratch = Scratch(np.zeros(25, np.int64), np.zeros(n, bool))
        done = world_step(rules, bodies, actions, outcome, scratch, Score(row, row_f))
        if done:
            break
    return field_columns(*field_costs(x, y, gx, gy, arrival, n, int(row[0])), n), arrival


def test_every_agent_home_costs_its_arrival_step():
    # Agent 0 arrives at step 1, agent 1 at step 3: the episode ends there.
    columns, arrival = play([(0, 0), (0, 4)], [(1, 0), (3, 4)],
                            [[RIGHT, RIGHT], [STAY, RIGHT], [STAY, RIGHT]], steps=10)
    assert arrival.tolist() == [1, 3]
    assert columns == {"csr": 1, "isr": 1.0, "soc": 4, "makespan": 3}


def test_an_agent_that_never_arrives_costs_the_episode_s_steps():
    # Agent 1 never moves: after 6 steps it costs 6, and the swarm is not complete.
    columns, arrival = play([(0, 0), (0, 4), (4, 0)], [(0, 2), (3, 4), (4, 1)],
                            [[DOWN, STAY, DOWN], [DOWN, STAY, STAY]], steps=6)
    assert arrival.tolist() == [2, 0, 1]
    assert columns == {"csr": 0, "isr": 2 / 3, "soc": 2 + 6 + 1, "makespan": 6}


def test_an_agent_off_its_goal_at_the_end_costs_the_episode_s_steps():
    # Under a rule that lets an arrived agent step aside, its arrival step may be set while it
    # ends elsewhere: it counts as not on its goal.
    x, y, gx, gy = ints([1, 2]), ints([0, 0]), ints([1, 3]), ints([0, 0])
    on_goal, soc, makespan = field_costs(x, y, gx, gy, ints([4, 7]), 2, 20)
    assert (on_goal, soc, makespan) == (1, 4 + 20, 20)
    assert field_columns(on_goal, soc, makespan, 2) == {"csr": 0, "isr": 0.5, "soc": 24,
                                                         "makespan": 20}


def test_the_field_s_columns_are_in_the_episode_rows():
    from nnql_swarm.world.engine import EPISODE_FIELDS
    from nnql_swarm.world.rules import TASK_COLUMNS

    assert EPISODE_FIELDS[-len(FIELD_COLUMNS + TASK_COLUMNS):] == FIELD_COLUMNS + TASK_COLUMNS


def small_bench(**changes) -> MapsBenchmark:
    options = dict(seeds=1, train_maps=1, train_episodes=4, train_agents=4, test_maps=1,
                   instances=2, agents=(4,), scratch_agents=(), max_steps=40)
    return MapsBenchmark(**{**options, **changes})


def test_frozen_play_writes_no_table_and_plays_the_learned_one():
    bench = small_bench()
    recorder = Recorder(None)
    tables = train(bench, 0, recorder)
    assert len(recorder.rows) == len(bench.learners) * bench.train_episodes
    shared, own = tables["path-nnql"], tables["ql"]
    assert shared[0].shape[0] == 1 and own[0].shape[0] == bench.train_agents
    map_seed = bench.test_map_seeds(0)[0]
    spec = map_spec("random", map_seed)
    batch = play_frozen(bench, tables, spec, map_seed, 6, recorder, {"phase": "frozen"})
    for run, variant in enumerate(bench.learners):
        q_ds, q_ca = tables[variant]
        for agent in range(6):
            assert np.array_equal(batch.q_ds[run, agent], q_ds[agent % len(q_ds)])
            assert np.array_equal(batch.q_ca[run, agent, :q_ca.shape[1]], q_ca[agent % len(q_ca)])
    assert (tables["path-nnql"][0] != bench.presets["path-nnql"]["optimistic"]).any(), \
        "training learned something"
    frozen = [row for row in recorder.rows if row["phase"] == "frozen"]
    assert [row["variant"] for row in frozen] == list(bench.variants) * bench.instances


def test_map_specs_come_from_the_generators_and_the_seeds_stay_apart():
    bench = MapsBenchmark()
    for family in ("random", "maze", "warehouse"):
        rows = generated(map_spec(family, 7), 0)
        assert 17 <= len(rows) <= 46
    assert set(bench.train_map_seeds(3)).isdisjoint(
        {s for seed in bench.seed_list for s in bench.test_map_seeds(seed)})
    with pytest.raises(ValueError, match="held-out"):
        MapsBenchmark(seeds=10 ** 6, train_maps=8).check()


@pytest.mark.parametrize("on_target", ["park", "step-aside"])
def test_every_variant_plays_the_benchmarks_on_target_rule(on_target):
    bench = MapsBenchmark(on_target=on_target)
    for variant in bench.variants:
        config = run_config(bench, variant, map_spec("random", 5), 5, 8, 1, True)
        assert config.on_target == on_target


def test_the_table_reads_seeds_and_ratios_by_hand():
    bench = small_bench(seeds=2, learners=("path-nnql", "ql"))

    def row(seed, variant, isr, soc, collisions):
        return {"phase": "frozen", "seed": seed, "family": "random", "agents": 4,
                "variant": variant, "instance": 0, "isr": isr, "csr": int(isr == 1.0),
                "soc": soc, "makespan": 10, "collisions": collisions, "agent_steps": soc,
                "shortest_sum": 20}

    rows = [row(0, "path-nnql", 1.0, 30, 1), row(0, "ql", 0.5, 60, 10), row(0, "oracle", 1.0, 20, 0),
            row(1, "path-nnql", 0.5, 40, 0), row(1, "ql", 0.25, 80, 20),
            row(1, "oracle", 1.0, 20, 0)]
    table = {r["variant"]: r for r in table_rows(bench, rows)}
    learner = table["path-nnql"]
    assert learner["isr"] == 0.75 and learner["csr"] == 0.5 and learner["seeds"] == 2
    assert learner["soc_vs_oracle"] == pytest.approx((30 / 20 + 40 / 20) / 2)
    assert learner["collisions_vs_ql_pct"] == pytest.approx((10.0 + 0.0) / 2)
    assert learner["isr_low"] < 0.75 < learner["isr_high"]
    assert table["oracle"]["soc_vs_oracle"] == 1.0


def test_a_tiny_benchmark_writes_its_table_episodes_and_curves(tmp_path):
    out = tmp_path / "maps"
    done = experiment(*TINY, "--out", str(out))
    assert done.returncode == 0, done.stderr
    table = read_csv(out / "maps_table.csv")
    for column in ("phase", "family", "agents", "variant", "seeds", "isr", "isr_low", "isr_high",
                   "csr", "soc", "soc_vs_oracle", "makespan", "collisions",
                   "collisions_vs_ql_pct", "steps_ratio"):
        assert column in table[0], column
    cells = {(r["phase"], r["family"], r["agents"], r["variant"]) for r in table}
    for family in ("random", "maze", "warehouse"):
        for agents in ("4", "6"):
            for variant in ("path-nnql", "ql", "oracle"):
                assert ("frozen", family, agents, variant) in cells
    assert ("scratch", "random", "4", "path-nnql") in cells
    assert all(r["soc_vs_oracle"] == "1.0000" for r in table if r["variant"] == "oracle")
    episodes = read_csv(out / "maps_episodes.csv")
    assert list(episodes[0]) == list(EPISODE_COLUMNS)
    assert {r["phase"] for r in episodes} == {"train", "frozen", "scratch"}
    assert len([r for r in episodes if r["phase"] == "frozen"]) == 2 * 3 * 2 * 2 * 3
    curves = read_csv(out / "maps_curves.csv")
    assert {r["curve"] for r in curves} >= {"train-path-nnql", "scratch-4-oracle"}
    assert (out / "maps_curves.rrd").stat().st_size > 0
    assert sorted(p.name for p in (out / "policies").iterdir()) == [
        "path-nnql-s0.npz", "path-nnql-s1.npz", "ql-s0.npz", "ql-s1.npz"]
    assert "| frozen | warehouse | 6 | oracle |" in (out / "maps_table.md").read_text()
    again = experiment(*TINY, "--out", str(out))
    assert again.returncode == 2 and "--force" in again.stderr


@pytest.mark.parametrize("args, message", [
    (["--agents", "0"], "at least 1"), (["--families", "city"], "families"),
    (["--set", "speed=3"], "OPTION=VALUE"), (["--set", "beta=2"], "beta"),
    (["--preset", "nobody"], "invalid choice"),
    (["--families", "mazes"], "POGEMA's (--suite pogema)"),
    (["--preset", "oracle", "--set", "beta=0.5"], "has none"), (["--train-agents", "5000"], "between"),
    (["--on-target", "stay"], "invalid choice"),
])
def test_bad_values_exit_2_with_one_line(args, message, tmp_path):
    done = experiment("maps", *args, "--out", str(tmp_path / "x"))
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr


def test_ctrl_c_keeps_every_episode_written(tmp_path):
    out = tmp_path / "big"
    process = subprocess.Popen(
        [sys.executable, str(EXPERIMENT), "maps", "--seeds", "50", "--out", str(out)], cwd=ROOT,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    episodes = out / "maps_episodes.csv"
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (
            not episodes.exists() or episodes.read_text().count("\n") < 20):
        time.sleep(0.2)
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "interrupted" in stderr and "Traceback" not in stderr
    text = episodes.read_text()
    assert text.endswith("\n")
    rows = list(csv.reader(text.splitlines()))
    assert len(rows) > 20 and all(len(row) == len(EPISODE_COLUMNS) for row in rows)
    assert not (out / "maps_table.csv").exists()
