"""The experiment CLI end to end (files, columns, determinism, bad options, Ctrl-C), its progress
bar, its statistics and its tables."""

import json
import math
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from nnql_swarm.experiment.paper import EpisodeMetrics, RunSpec
from nnql_swarm.experiment.report import (
    EPISODE_COLUMNS, PAPER_TABLE1, TABLE1_COLUMNS, ResultGrid, summarize, table1_markdown, table1_rows,
)
from nnql_swarm.experiment.stats import mean_interval, t_quantile
from nnql_swarm.launch.cli import progress
from tests.swarm_helpers import EXPERIMENT, ROOT, experiment, read_csv

SHORT = ["--episodes", "20", "--seeds", "2", "--ks", "1,2"]


def test_short_run_writes_every_file(tmp_path):
    out = tmp_path / "tmp"
    done = experiment(*SHORT, "--out", str(out))
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr

    table = read_csv(out / "table1.csv")
    assert list(table[0].keys()) == list(TABLE1_COLUMNS)
    assert [row["random_step"] for row in table] == ["1", "2"]
    for row in table:
        for column in ("ql_collisions", "nnql_collisions", "decrease_pct", "diff_ci_low", "diff_ci_high"):
            float(row[column])

    episodes = read_csv(out / "episodes.csv")
    assert list(episodes[0].keys()) == list(EPISODE_COLUMNS)
    assert len(episodes) == 2 * 2 * 2 * 20  # algos x ks x seeds x episodes
    assert {(r["algo"], r["random_step"], r["seed"]) for r in episodes} == {
        (a, k, s) for a in ("ql", "nnql") for k in ("1", "2") for s in ("0", "1")
    }
    first = episodes[0]
    assert float(first["reward_total"]) == pytest.approx(float(first["reward_ds"]) + float(first["reward_ca"]))
    # Table 1's numbers are the per-run totals of episodes.csv, averaged over seeds.
    totals = [sum(int(r["collisions"]) for r in episodes if (r["algo"], r["random_step"], r["seed"]) == ("ql", "2", s))
              for s in ("0", "1")]
    assert float(table[1]["ql_collisions"]) == pytest.approx(np.mean(totals))

    config = json.loads((out / "config.json").read_text())
    assert config["settings"]["episodes"] == 20 and config["settings"]["max_steps"] == 100
    assert {k: config["settings"][k] for k in ("alpha", "gamma", "beta")} == {
        "alpha": 0.9, "gamma": 0.6, "beta": 0.5}
    assert config["seeds"] == [0, 1] and config["random_steps"] == [1, 2]

    markdown = (out / "table1.md").read_text()
    assert "| 860.4 | 849.5 | 1.27 |" in markdown and "40.18" in markdown
    for name in ("steps", "rewards", "cumulative_collisions", "collisions", "collisions_vs_k"):
        assert (out / f"{name}.png").stat().st_size > 1000


@pytest.mark.full
def test_same_seed_gives_byte_identical_results(tmp_path):
    outputs = []
    for name in ("a", "b"):
        done = experiment(*SHORT, "--seed-base", "5", "--no-plots", "--out", str(tmp_path / name))
        assert done.returncode == 0, done.stderr
        outputs.append(tmp_path / name)
    for file in ("episodes.csv", "table1.csv", "table1.md"):
        assert (outputs[0] / file).read_bytes() == (outputs[1] / file).read_bytes(), file


@pytest.mark.parametrize(
    "args",
    [
        ["--seeds", "0"],
        ["--seeds", "two"],
        ["--ks", "0-3"],
        ["--ks", "5-2"],
        ["--ks", "a,b"],
        ["--algos", "ql,sarsa"],
        ["--beta", "1.5"],
        ["--beta", "nan"],
        ["--episodes", "-1"],
        ["--grid", "11by11"],
        ["--grid", "2x1", "--obstacles", "3"],
        ["--figure-k", "7", "--ks", "1,2"],
        ["--workers", "0"],
        ["--no-such-option"],
    ],
)
def test_bad_options_exit_2_with_one_line(args, tmp_path):
    done = experiment(*args, "--out", str(tmp_path / "never"), timeout=30)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("experiment.py: error:"), done.stderr
    assert not (tmp_path / "never").exists()


def test_refuses_to_overwrite_results_unless_forced(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "table1.csv").write_text("old\n")
    refused = experiment("--episodes", "2", "--seeds", "1", "--ks", "2", "--no-plots", "--out", str(out))
    assert refused.returncode == 2 and "--force" in refused.stderr
    assert (out / "table1.csv").read_text() == "old\n"
    forced = experiment("--episodes", "2", "--seeds", "1", "--ks", "2", "--no-plots", "--force", "--out", str(out))
    assert forced.returncode == 0, forced.stderr
    assert (out / "table1.csv").read_text() != "old\n"


@pytest.mark.full
@pytest.mark.parametrize("workers", ["1", "2"])
def test_ctrl_c_stops_cleanly_with_exit_130(tmp_path, workers):
    # 100 times the default seeds, minutes of work: the whole default run takes under 3 s, so a
    # Ctrl-C half a second after its first line could otherwise come after its end. SIGINT as in a
    # terminal's foreground: a shell's background job (`make test &`) ignores it, and Python
    # then never raises KeyboardInterrupt.
    process = subprocess.Popen(
        [sys.executable, str(EXPERIMENT), "--no-plots", "--workers", workers, "--seeds", "1000",
         "--out", str(tmp_path / "big")],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 60
    first_line = process.stderr.readline()  # the progress bar's first line: the run has started
    assert "episodes" in first_line, first_line
    time.sleep(0.5)
    assert time.monotonic() < deadline
    os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the whole process group
    _, stderr = process.communicate(timeout=30)
    assert process.returncode == 130
    assert "interrupted" in stderr and "Traceback" not in stderr
    assert not (tmp_path / "big" / "table1.csv").exists()


@pytest.mark.parametrize(
    "df, quantile",
    [(1, 12.706204736), (2, 4.302652730), (4, 2.776445105), (9, 2.262157163), (29, 2.045229642),
     (120, 1.979930405)],
)
def test_t_quantile_matches_tables(df, quantile):
    assert t_quantile(0.975, df) == pytest.approx(quantile, rel=1e-8)
    assert t_quantile(0.025, df) == pytest.approx(-quantile, rel=1e-8)


def test_mean_interval():
    interval = mean_interval(np.array([1.0, 2.0, 3.0, 4.0]))
    half = t_quantile(0.975, 3) * np.std([1, 2, 3, 4], ddof=1) / 2
    assert (interval.mean, interval.low, interval.high) == pytest.approx((2.5, 2.5 - half, 2.5 + half))
    assert math.isnan(mean_interval(np.array([3.0])).low)


def synthetic_grid() -> ResultGrid:
    """Two seeds, k = 1 and 2, with hand-made collisions: nnQL halves QL at k = 2."""
    specs = [RunSpec(a, k, s) for a in ("ql", "nnql") for k in (1, 2) for s in (0, 1)]
    metrics = EpisodeMetrics.empty(len(specs), 2)
    per_run = {("ql", 1): (50, 52), ("nnql", 1): (50, 52), ("ql", 2): (40, 44), ("nnql", 2): (20, 22)}
    for row, spec in enumerate(specs):
        metrics.collisions[row] = [per_run[spec.algo, spec.random_step][spec.seed], 0]
        metrics.steps[row] = [10, 6]
        metrics.shortest[row] = [4, 3]
    return ResultGrid(specs, metrics)


def test_table1_rows_and_summary_by_hand():
    grid = synthetic_grid()
    rows = table1_rows(grid)
    assert rows[1]["ql_collisions"] == 42 and rows[1]["nnql_collisions"] == 21
    assert rows[1]["decrease_pct"] == pytest.approx(50.0)
    assert rows[1]["diff_collisions"] == 21
    assert rows[0]["diff_ci_low"] == rows[0]["diff_ci_high"] == 0
    summary = summarize(grid, figure_k=2)
    assert summary.learning_ks == [2] and summary.decrease_pct == pytest.approx(50.0)
    assert summary.steps_learned == {"ql": 8.0, "nnql": 8.0} and summary.shortest_learned == 3.5
    assert summary.diff.mean == 21 and summary.diff.above_zero
    markdown = table1_markdown(rows, summary)
    assert "| 2 | 42.0 |" in markdown and f"{PAPER_TABLE1[2][0]:.1f}" in markdown


SWARM_SHORT = ["swarm", "--agents", "6", "--seeds", "2", "--seed-base", "4", "--episodes", "20",
               "--max-steps", "40"]


@pytest.mark.full
def test_swarm_experiment_writes_its_table_runs_curves_and_recording(tmp_path):
    out = tmp_path / "swarm"
    result = experiment(*SWARM_SHORT, "--out", str(out), timeout=300)
    assert result.returncode == 0, result.stderr
    rows = read_csv(out / "swarm_table.csv")
    assert [r["variant"] for r in rows] == ["ql", "nnql", "best-ql", "best-nnql", "shield-ql",
                                            "shield-nnql", "path-nnql", "nnql-n2", "daql", "oracle"]
    for column in ("variant", "seeds", "arrival_4_8", "arrival_16_20", "steps_ratio_16_20",
                   "collisions", "collisions_ci_low", "collisions_ci_high", "decrease_vs_ql_pct"):
        assert column in rows[0]
    by = {r["variant"]: r for r in rows}
    assert by["oracle"]["collisions"] == "0.0000" and by["oracle"]["arrival_16_20"] == "1.0000"
    assert by["nnql"]["vs"] == "ql" and by["shield-nnql"]["vs"] == "shield-ql"
    for name in ("swarm_table.md", "swarm_arrival.png", "swarm_steps_ratio.png",
                 "swarm_collisions.png", "swarm_curves.rrd", "config.json"):
        assert (out / name).stat().st_size > 0, name
    run = out / "runs" / "best-nnql-s5"
    assert len(read_csv(run / "episodes.csv")) == 20
    assert json.loads((run / "config.json").read_text())["shared"] is True
    rerun = os.path.join(os.path.dirname(sys.executable), "rerun")
    verify = subprocess.run([rerun, "rrd", "verify", str(out / "swarm_curves.rrd")],
                            capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


@pytest.mark.full
def test_the_distributed_swarm_plays_the_experiments_run_of_best_nnql(tmp_path):
    """One seed of best-nnql (one table shared over Zenoh): the distributed swarm writes the very
    episodes.csv the experiment's runner wrote, wall-clock columns aside."""
    from nnql_swarm.world.engine import EPISODE_FIELDS

    out = tmp_path / "swarm"
    result = experiment("swarm", "--variants", "best-nnql", "--agents", "8", "--seeds", "1",
                        "--seed-base", "3", "--episodes", "25", "--no-plots", "--out", str(out),
                        timeout=300)
    assert result.returncode == 0, result.stderr
    swarm = subprocess.run(
        [sys.executable, "launch/swarm.py", "--preset", "best-nnql", "--agents", "8", "--seed",
         "3", "--episodes", "25", "--no-record", "--no-progress", "--out", str(tmp_path / "dist")],
        cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert swarm.returncode == 0, swarm.stderr
    ours = read_csv(out / "runs" / "best-nnql-s3" / "episodes.csv")
    theirs = read_csv(tmp_path / "dist" / "episodes.csv")
    assert [[r[f] for f in EPISODE_FIELDS] for r in theirs] == [
        [r[f] for f in EPISODE_FIELDS] for r in ours]


@pytest.mark.parametrize("args, message", [
    (["swarm", "--variants", "sarsa"], "choose variants"),
    (["swarm", "--agents", "80"], "distinct start and goal cells"),
    (["swarm", "--episodes", "2"], "must be at least 5"),
])
def test_swarm_experiment_bad_options_exit_2_with_one_line(args, message, tmp_path):
    result = experiment(*args, "--out", str(tmp_path / "x"))
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.stderr


def test_a_progress_bar_where_stderr_is_no_terminal_writes_whole_lines(capsys):
    with progress(10, "step", "work") as bar:
        for _ in range(10):
            bar.update()
    lines = capsys.readouterr().err.splitlines()
    assert lines and all("\r" not in line for line in lines)
    assert lines[-1].startswith("work: 100%") and "10/10" in lines[-1]
    assert sum("10/10" in line for line in lines) == 1  # closing does not repeat the last line
