"""Tables of the paper's experiment: Table 1 with confidence intervals, per-episode CSV, summary.

Everything here reads the per (run, episode) metrics of :func:`experiment.paper.run_batch` and the specs
that produced them; nothing runs an experiment. A run's score in Table 1 is its total number of
collisions over all episodes; the table shows the mean over seeds per random step ``k``.
"""

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nnql_swarm.experiment.paper import ALGOS, EpisodeMetrics, RunSpec
from nnql_swarm.experiment.stats import CONFIDENCE, Interval, mean_interval

PAPER_TABLE1 = {
    # k: (QL collisions, nnQL collisions, decrease in %), Table 1 of the paper
    1: (860.4, 849.5, 1.27),
    2: (632.9, 417.9, 33.97),
    3: (534.8, 302.6, 43.42),
    4: (499.0, 252.1, 49.48),
    5: (486.8, 241.0, 50.49),
    6: (439.8, 216.5, 50.77),
    7: (441.6, 195.4, 55.75),
    8: (425.1, 209.0, 50.84),
    9: (408.5, 189.6, 53.59),
    10: (413.3, 202.3, 51.05),
}
PAPER_TABLE1_MEANS = (514.2, 307.6, 40.18)

LEARNED_EPISODES = 100
"""Steps "after learning" are averaged over this many last episodes of each run."""

ALGO_NAMES = {"ql": "QL", "nnql": "nnQL"}

EPISODE_COLUMNS = (
    "algo", "random_step", "seed", "episode", "steps", "shortest", "collisions",
    "reward_ds", "reward_ca", "reward_total", "arrived",
)


@dataclass(frozen=True)
class ResultGrid:
    """Metrics rearranged by (algo, k, seed); missing combinations are absent from ``rows``."""

    specs: list[RunSpec]
    metrics: EpisodeMetrics

    @property
    def algos(self) -> list[str]:
        return [a for a in ALGOS if any(s.algo == a for s in self.specs)]

    @property
    def ks(self) -> list[int]:
        return sorted({s.random_step for s in self.specs})

    @property
    def seeds(self) -> list[int]:
        return sorted({s.seed for s in self.specs})

    def rows(self, algo: str, k: int) -> np.ndarray:
        """Row indices of one (algo, k) cell, ordered by seed."""
        picked = [(s.seed, i) for i, s in enumerate(self.specs) if s.algo == algo and s.random_step == k]
        return np.array([i for _, i in sorted(picked)], dtype=np.int64)

    def total_collisions(self, algo: str, k: int) -> np.ndarray:
        """Per seed: the run's collisions summed over all its episodes."""
        return self.metrics.collisions[self.rows(algo, k)].sum(axis=1)

    def learned_steps(self, algo: str, k: int) -> tuple[float, float]:
        """Mean steps per episode and mean shortest steps over the last episodes, over seeds."""
        rows = self.rows(algo, k)
        last = slice(-min(LEARNED_EPISODES, self.metrics.steps.shape[1]), None)
        return (
            float(self.metrics.steps[rows, last].mean()),
            float(self.metrics.shortest[rows, last].mean()),
        )

    def paired(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """QL and nnQL totals of the seeds both ran at ``k`` (None if either is missing)."""
        if not {"ql", "nnql"} <= set(self.algos):
            return None
        ql = {self.specs[i].seed: i for i in self.rows("ql", k)}
        nnql = {self.specs[i].seed: i for i in self.rows("nnql", k)}
        common = sorted(ql.keys() & nnql.keys())
        if not common:
            return None
        totals = self.metrics.collisions.sum(axis=1)
        return totals[[ql[s] for s in common]], totals[[nnql[s] for s in common]]


def table1_rows(grid: ResultGrid) -> list[dict[str, float | int]]:
    """One row per k: each algo's mean total collisions (with CI), the paired difference, decrease."""
    missing = Interval(math.nan, math.nan, math.nan, 0)
    rows = []
    for k in grid.ks:
        row: dict[str, float | int] = {"random_step": k, "seeds": len(grid.seeds)}
        row["shortest_learned"] = math.nan
        for algo in ALGOS:
            ran = algo in grid.algos and grid.rows(algo, k).size > 0
            interval = mean_interval(grid.total_collisions(algo, k)) if ran else missing
            steps, shortest = grid.learned_steps(algo, k) if ran else (math.nan, math.nan)
            row[f"{algo}_collisions"] = interval.mean
            row[f"{algo}_ci_low"] = interval.low
            row[f"{algo}_ci_high"] = interval.high
            row[f"{algo}_steps_learned"] = steps
            if ran:
                row["shortest_learned"] = shortest  # the same scenarios for every algo
        pair = grid.paired(k)
        diff = mean_interval(pair[0] - pair[1]) if pair else missing
        row["diff_collisions"] = diff.mean
        row["diff_ci_low"] = diff.low
        row["diff_ci_high"] = diff.high
        row["decrease_pct"] = _decrease(row["ql_collisions"], row["nnql_collisions"])
        rows.append(row)
    return rows


TABLE1_COLUMNS = (
    "random_step", "seeds",
    "ql_collisions", "ql_ci_low", "ql_ci_high",
    "nnql_collisions", "nnql_ci_low", "nnql_ci_high",
    "diff_collisions", "diff_ci_low", "diff_ci_high", "decrease_pct",
    "ql_steps_learned", "nnql_steps_learned", "shortest_learned",
)


@dataclass(frozen=True)
class Summary:
    """The headline numbers of a run of the experiment."""

    learning_ks: list[int]
    ql_mean: float
    nnql_mean: float
    decrease_pct: float
    diff: Interval
    all_ks_decrease_pct: float
    figure_k: int
    learned_episodes: int
    steps_learned: dict[str, float]
    shortest_learned: float

    def steps_ratio(self, algo: str) -> float:
        return self.steps_learned.get(algo, math.nan) / self.shortest_learned


def summarize(grid: ResultGrid, figure_k: int) -> Summary:
    """Headline numbers: decrease over k >= 2 (k = 1 is all random, no learning shows), steps."""
    learning_ks = [k for k in grid.ks if k >= 2] or grid.ks
    ql = _pooled(grid, "ql", learning_ks)
    nnql = _pooled(grid, "nnql", learning_ks)
    pairs = [p for p in (grid.paired(k) for k in learning_ks) if p is not None]
    if pairs and len(pairs) == len(learning_ks):
        per_seed = np.mean([p[0] - p[1] for p in pairs], axis=0)
        diff = mean_interval(per_seed)
    else:
        diff = Interval(math.nan, math.nan, math.nan, 0)
    steps, shortest = {}, math.nan
    for algo in grid.algos:
        steps[algo], shortest = grid.learned_steps(algo, figure_k)
    return Summary(
        learning_ks=learning_ks,
        ql_mean=ql,
        nnql_mean=nnql,
        decrease_pct=_decrease(ql, nnql),
        diff=diff,
        all_ks_decrease_pct=_decrease(_pooled(grid, "ql", grid.ks), _pooled(grid, "nnql", grid.ks)),
        figure_k=figure_k,
        learned_episodes=min(LEARNED_EPISODES, grid.metrics.steps.shape[1]),
        steps_learned=steps,
        shortest_learned=shortest,
    )


def _pooled(grid: ResultGrid, algo: str, ks: list[int]) -> float:
    if algo not in grid.algos:
        return math.nan
    return float(np.mean([grid.total_collisions(algo, k).mean() for k in ks]))


def _decrease(ql: float, nnql: float) -> float:
    """Percentage by which nnQL's collisions are below QL's (the paper's last column)."""
    if math.isnan(ql) or math.isnan(nnql) or ql == 0:
        return math.nan
    return 100.0 * (ql - nnql) / ql


def _cell(value: float | int | str, digits: int = 2) -> str:
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.{digits}f}"
    return str(value)


def write_table1_csv(path: Path, rows: list[dict]) -> None:
    with open(path, "w", newline="") as out:
        writer = csv.DictWriter(out, fieldnames=TABLE1_COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({c: _cell(row[c], 3) for c in TABLE1_COLUMNS})


def summary_lines(summary: Summary) -> list[str]:
    """The summary as plain sentences (Markdown list items without the bullet)."""
    ks = summary.learning_ks
    k_range = f"k = {ks[0]}..{ks[-1]}" if len(ks) > 1 else f"k = {ks[0]}"
    diff = summary.diff
    if diff.n >= 2:
        verdict = "above zero" if diff.above_zero else "not above zero"
        diff_text = (
            f"QL - nnQL = {diff.mean:.1f} collisions per run, {CONFIDENCE:.0%} CI "
            f"[{diff.low:.1f}, {diff.high:.1f}] over {diff.n} seeds: {verdict}"
        )
    else:
        diff_text = "the interval of the difference needs both algorithms and at least 2 seeds"
    lines = [
        f"Mean collisions over {k_range}: QL {_cell(summary.ql_mean, 1)}, "
        f"nnQL {_cell(summary.nnql_mean, 1)}, decrease {_cell(summary.decrease_pct)} % "
        f"(paper, k = 2..10: {_paper_learning_decrease():.2f} %).",
        f"Paired difference over {k_range}: {diff_text}.",
        f"Decrease of the means over all k run (the paper's last row, {PAPER_TABLE1_MEANS[2]:.2f} %): "
        f"{_cell(summary.all_ks_decrease_pct)} %.",
    ]
    for algo, steps in summary.steps_learned.items():
        lines.append(
            f"{ALGO_NAMES[algo]} at k = {summary.figure_k}, last {summary.learned_episodes} "
            f"episodes: {steps:.2f} steps per episode vs {summary.shortest_learned:.2f} shortest "
            f"possible ({summary.steps_ratio(algo):.2f}x)."
        )
    return lines


def _paper_learning_decrease() -> float:
    ql = float(np.mean([PAPER_TABLE1[k][0] for k in range(2, 11)]))
    nnql = float(np.mean([PAPER_TABLE1[k][1] for k in range(2, 11)]))
    return float(_decrease(ql, nnql))


def table1_markdown(rows: list[dict], summary: Summary) -> str:
    """Our Table 1 beside the paper's, with 95 % intervals, and the summary lines."""
    header = [
        "k", "QL", "QL 95 % CI", "nnQL", "nnQL 95 % CI", "QL - nnQL [95 % CI]", "decrease %",
        "paper QL", "paper nnQL", "paper decrease %",
    ]
    body = []
    for row in rows:
        diff_interval = _interval_cell(row["diff_ci_low"], row["diff_ci_high"])
        diff = f"{_cell(row['diff_collisions'], 1)} {diff_interval}"
        body.append([
            str(row["random_step"]),
            _cell(row["ql_collisions"], 1),
            _interval_cell(row["ql_ci_low"], row["ql_ci_high"]),
            _cell(row["nnql_collisions"], 1),
            _interval_cell(row["nnql_ci_low"], row["nnql_ci_high"]),
            diff.strip(),
            _cell(row["decrease_pct"]),
            *_paper_cells(PAPER_TABLE1.get(int(row["random_step"]))),
        ])
    body.append([
        "mean",
        _cell(float(np.mean([r["ql_collisions"] for r in rows])), 1), "",
        _cell(float(np.mean([r["nnql_collisions"] for r in rows])), 1), "", "",
        _cell(summary.all_ks_decrease_pct),
        *_paper_cells(PAPER_TABLE1_MEANS),
    ])
    seeds = rows[0]["seeds"] if rows else 0
    lines = [
        f"# Table 1: total collisions per run, mean over {seeds} seeds",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---:|" * len(header),
        *("| " + " | ".join(cells) + " |" for cells in body),
        "",
        *(f"- {line}" for line in summary_lines(summary)),
        "",
    ]
    return "\n".join(lines)


def _paper_cells(paper_row: tuple[float, float, float] | None) -> list[str]:
    if paper_row is None:
        return ["", "", ""]
    ql, nnql, decrease = paper_row
    return [f"{ql:.1f}", f"{nnql:.1f}", f"{decrease:.2f}"]


def _interval_cell(low: float, high: float) -> str:
    if math.isnan(low) or math.isnan(high):
        return ""
    return f"[{low:.1f}, {high:.1f}]"


def write_episodes_csv(path: Path, specs: list[RunSpec], metrics: EpisodeMetrics) -> None:
    """One row per (algo, k, seed, episode), in that order; floats in shortest round-trip form."""

    def spec_order(i: int) -> tuple[int, int, int]:
        return ALGOS.index(specs[i].algo), specs[i].random_step, specs[i].seed

    m = metrics
    with open(path, "w", newline="") as out:
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(EPISODE_COLUMNS)
        for i in sorted(range(len(specs)), key=spec_order):
            spec = specs[i]
            ds, ca = m.reward_ds[i].tolist(), m.reward_ca[i].tolist()
            writer.writerows(
                (spec.algo, spec.random_step, spec.seed, e, steps, shortest, collisions,
                 repr(ds[e]), repr(ca[e]), repr(ds[e] + ca[e]), int(arrived))
                for e, (steps, shortest, collisions, arrived) in enumerate(zip(
                    m.steps[i].tolist(), m.shortest[i].tolist(), m.collisions[i].tolist(),
                    m.arrived[i].tolist(),
                ))
            )
