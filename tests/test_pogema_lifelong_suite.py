"""``launch/experiment.py maps --suite pogema --tasks lifelong``: frozen play on POGEMA's lifelong
instances, throughput per family and variant beside the published figures
(``experiment.published``) and against the oracle's, each instance the one the swarm plays from
its ``.map`` and ``.goals``; a bad combination is one line."""

import math

import pytest

from nnql_swarm.experiment.published import (
    THROUGHPUT, THROUGHPUT_METHODS, THROUGHPUT_SOURCES,
)
from nnql_swarm.world.pogema_instances import FAMILIES, INSTANCES, goals_files, read_lifelong
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import experiment, read_csv, run_swarm

VARIANTS = ("pibt-nnql", "ql", "oracle")
TINY = ["maps", "--suite", "pogema", "--tasks", "lifelong", "--preset", "pibt-nnql", "--seeds",
        "1", "--train-maps", "1", "--train-episodes", "3", "--instances", "2", "--agents", "8",
        "--families", "random,mazes", "--scratch-agents", "8", "--scratch-episodes", "5"]


def test_every_published_throughput_is_at_a_published_lifelong_count_and_has_its_source():
    assert set(THROUGHPUT_SOURCES) == set(THROUGHPUT_METHODS)
    assert set(THROUGHPUT) == set(FAMILIES)
    for family, methods in THROUGHPUT.items():
        assert set(methods) == set(THROUGHPUT_METHODS)
        for figures in methods.values():
            assert set(figures) == set(FAMILIES[family].lifelong_agents)
            assert all(0 < v < 10 for v in figures.values())


def test_each_family_s_lifelong_instances_hold_its_largest_published_count():
    for family in FAMILIES.values():
        files = goals_files(family.name)
        assert len(files) == family.instances
        instance = read_lifelong(files[0], max(family.lifelong_agents))
        assert len(instance.scenario) == len(instance.goal_lists) == max(family.lifelong_agents)
        assert family.lifelong_steps in (128, 256)


def test_the_lifelong_suite_plays_pogema_s_instances_beside_the_published(tmp_path):
    out = tmp_path / "lifelong"
    done = experiment(*TINY, "--out", str(out))
    assert done.returncode == 0, done.stderr
    episodes = [r for r in read_csv(out / "maps_episodes.csv") if r["phase"] == "frozen"]
    assert len(episodes) == 2 * 2 * len(VARIANTS)
    for family in ("random", "mazes"):
        played = [r for r in episodes if r["family"] == family]
        assert sorted({r["map"] for r in played}) == [p.stem for p in goals_files(family)[:2]]
        assert {(r["agents"], r["variant"]) for r in played} == {("8", v) for v in VARIANTS}
        assert {int(r["steps"]) for r in played} == {FAMILIES[family].lifelong_steps}
        for row in played:
            assert math.isclose(float(row["throughput"]), int(row["goals"]) / int(row["steps"]))
            if row["variant"] != "ql":
                assert int(row["goals"]) > 0 and int(row["collisions"]) == 0, row
    table = read_csv(out / "maps_table.csv")
    assert {(r["family"], r["variant"]) for r in table} == {
        (f, v) for f in ("random", "mazes") for v in VARIANTS}
    for row in table:
        assert {"throughput", "throughput_vs_oracle", "goals"} <= set(row)
        assert "csr" not in row
        if row["variant"] == "oracle":
            assert float(row["throughput_vs_oracle"]) == 0
    text = (out / "maps_table.md").read_text()
    assert "| family | agents | pibt-nnql | ql | oracle | RHCR | Follower | MATS-LP |" in text
    assert "| 0.63 | 0.60 | 0.61 |" in text  # random at 8 agents, published
    assert "| 0.48 | 0.45 | 0.46 |" in text  # mazes at 8 agents, published
    assert all(THROUGHPUT_SOURCES[m] in text for m in THROUGHPUT_METHODS)
    assert "## Learning against the oracle (PIBT-greedy), same instances" in text
    assert (out / "policies" / "pibt-nnql-s0.npz").exists()

    # learning from scratch: every variant on the first random instance, episode after episode
    scratch = [r for r in read_csv(out / "maps_episodes.csv") if r["phase"] == "scratch"]
    first = goals_files("random")[0].stem
    assert {(r["map"], r["agents"]) for r in scratch} == {(first, "8")}
    assert sorted((r["variant"], r["instance"]) for r in scratch) == sorted(
        (v, str(e)) for v in VARIANTS for e in range(5))
    oracle_scratch = [r for r in scratch if r["variant"] == "oracle"]
    assert all(float(r["throughput"]) > 0 for r in oracle_scratch)
    curves = read_csv(out / "maps_curves.csv")
    assert {r["curve"] for r in curves if r["metric"] == "throughput"} == {
        f"scratch-8-{v}" for v in VARIANTS}

    # the oracle's episode on each random instance is the swarm's on its .map and .goals
    for index in (0, 1):
        oracle = next(r for r in episodes if r["variant"] == "oracle"
                      and r["family"] == "random" and r["instance"] == str(index))
        instance = read_lifelong(goals_files("random")[index], 8)
        swarm = tmp_path / f"swarm{index}"
        run = run_swarm(swarm, "--map", str(INSTANCES / "random" / instance.map_name),
                        "--goals", str(goals_files("random")[index]), "--agents", "8",
                        "--tasks", "lifelong", "--max-steps", "256", "--preset", "oracle",
                        "--seed", "0", "--episodes", "1", "--in-process", "--no-record")
        assert run.returncode == 0, run.stderr
        alone = read_episodes(swarm / "episodes.csv")[0]
        for column in ("steps", "goals", "throughput", "collisions", "agent_steps"):
            assert alone[column] == oracle[column], column


@pytest.mark.parametrize("args, message", [
    (["--tasks", "lifelong"], "--tasks lifelong plays POGEMA's lifelong instances: add --suite "
                              "pogema"),
    (["--suite", "pogema", "--tasks", "lifelong", "--agents", "65", "--families", "mazes"],
     "lists 64 agents, not 65"),
    (["--suite", "pogema", "--tasks", "lifelong", "--pogema-dir", "/nonexistent"],
     "holds no .goals file"),
])
def test_bad_combinations_exit_2_with_one_line(args, message, tmp_path):
    done = experiment("maps", *args, "--out", str(tmp_path / "x"))
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
