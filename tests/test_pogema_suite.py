"""``launch/experiment.py maps --suite pogema``: frozen play on POGEMA's own instances, rows per
family and variant beside the published figures (``experiment.published``), each instance the
one the swarm plays from its ``.map`` and ``.scen``; bad values are one line."""

import pytest

from nnql_swarm.experiment.published import CSR, METHODS, SOC_OVER_LOWER_BOUND, SOURCES
from nnql_swarm.world.pogema_instances import FAMILIES, INSTANCES, scen_files
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import experiment, read_csv, run_swarm

TINY = ["maps", "--suite", "pogema", "--seeds", "1", "--train-maps", "1", "--train-episodes",
        "3", "--instances", "2", "--agents", "8"]


def test_every_published_figure_is_at_a_published_agent_count_and_has_its_source():
    assert set(SOURCES) == set(METHODS)
    for table in (CSR, SOC_OVER_LOWER_BOUND):
        for family, methods in table.items():
            assert set(methods) <= set(METHODS)
            for figures in methods.values():
                assert set(figures) == set(FAMILIES[family].agents)
                assert all(0 <= v <= 1 for v in figures.values()) or table is not CSR
    assert set(CSR) == set(FAMILIES)


def test_the_suite_plays_pogema_s_instances_and_prints_our_rows_beside_the_published(tmp_path):
    out = tmp_path / "pogema"
    done = experiment(*TINY, "--out", str(out))
    assert done.returncode == 0, done.stderr
    episodes = [r for r in read_csv(out / "maps_episodes.csv") if r["phase"] == "frozen"]
    variants = ("path-nnql", "ql", "oracle")
    assert len(episodes) == len(FAMILIES) * 2 * len(variants)
    for family in FAMILIES:
        played = [r for r in episodes if r["family"] == family]
        first_two = [p.stem for p in scen_files(family)[:2]]
        assert sorted({r["map"] for r in played}) == first_two
        assert {(r["agents"], r["variant"]) for r in played} == {("8", v) for v in variants}
        limit = FAMILIES[family].max_steps
        assert all(int(r["steps"]) <= limit for r in played)
    table = read_csv(out / "maps_table.csv")
    assert {(r["family"], r["variant"]) for r in table} == {
        (f, v) for f in FAMILIES for v in variants}
    assert "soc_vs_lb" in table[0]
    text = (out / "maps_table.md").read_text()
    assert "| family | agents | path-nnql | ql | oracle | LaCAM | MAPF-GPT-DDG | MAPF-GPT-85M " \
           "| SCRIMP | DCC |" in text
    assert "| 1.00 | 1.00 | 1.00 | 1.00 | 1.00 |" in text  # random at 8 agents, published
    assert "| 1.00 | 1.00 | 1.00 | 1.00 | 0.96 |" in text  # mazes at 8 agents, published
    assert all(SOURCES[m] in text for m in METHODS)
    assert (out / "policies" / "path-nnql-s0.npz").exists()

    # the oracle's episode on the first random instance is the swarm's on its .map and .scen
    oracle = next(r for r in episodes if r["variant"] == "oracle" and r["family"] == "random"
                  and r["instance"] == "0")
    stem = oracle["map"]
    run = run_swarm(tmp_path / "swarm", "--map", str(INSTANCES / "random" / f"{stem}.map"),
                    "--scen", str(INSTANCES / "random" / f"{stem}.scen"), "--agents", "8",
                    "--max-steps", "128", "--on-target", "step-aside", "--preset", "oracle",
                    "--episodes", "1", "--in-process", "--no-record")
    assert run.returncode == 0, run.stderr
    alone = read_episodes(tmp_path / "swarm" / "episodes.csv")[0]
    for column in ("steps", "csr", "isr", "soc", "makespan", "shortest_sum"):
        assert alone[column] == oracle[column], column


def test_the_oracle_alone_trains_nothing(tmp_path):
    out = tmp_path / "oracle"
    done = experiment("maps", "--suite", "pogema", "--preset", "oracle", "--seeds", "1",
                      "--instances", "1", "--families", "warehouse", "--out", str(out))
    assert done.returncode == 0, done.stderr
    episodes = read_csv(out / "maps_episodes.csv")
    assert {r["phase"] for r in episodes} == {"frozen"}
    assert {(r["agents"], r["variant"]) for r in episodes} == {
        (str(a), "oracle") for a in FAMILIES["warehouse"].agents}
    assert "| warehouse | 192 | " in (out / "maps_table.md").read_text()
    assert not (out / "policies").exists()


@pytest.mark.parametrize("args, message", [
    (["--families", "maze"], "'maze' is not one of POGEMA's"),
    (["--instances", "129"], "random has 128"),
    (["--agents", "65", "--families", "mazes"], "65 agents need 65 scenario lines"),
    (["--pogema-dir", "/nonexistent"], "holds no .scen file"),
])
def test_bad_values_exit_2_with_one_line(args, message, tmp_path):
    done = experiment("maps", "--suite", "pogema", *args, "--out", str(tmp_path / "x"))
    assert done.returncode == 2
    assert message in done.stderr and len(done.stderr.strip().splitlines()) == 1, done.stderr
