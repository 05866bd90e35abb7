"""The paper's figures (Figs. 5-13) as PNG files, drawn with matplotlib's Agg backend.

matplotlib is an optional dependency (the ``plot`` extra): :func:`require_matplotlib` says so in
one clear line, and nothing else in the project imports it.
"""

from pathlib import Path

import numpy as np

from nnql_swarm.experiment.report import ALGO_NAMES as ALGO_LABELS
from nnql_swarm.experiment.report import PAPER_TABLE1, ResultGrid, table1_rows

ALGO_COLOURS = {"ql": "tab:red", "nnql": "tab:blue"}
FIGURE_FILES = (
    "steps.png", "rewards.png", "cumulative_collisions.png", "collisions.png", "collisions_vs_k.png",
)


class MissingMatplotlib(RuntimeError):
    """Raised when figures are asked for without matplotlib installed."""


def require_matplotlib():
    """Import matplotlib with the Agg backend, or raise one clear line on how to get it."""
    try:
        import matplotlib
    except ImportError as error:
        raise MissingMatplotlib(
            "figures need matplotlib: pip install -e '.[plot]' (or pass --no-plots)"
        ) from error
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def write_figures(out_dir: Path, grid: ResultGrid, figure_k: int) -> list[Path]:
    """Draw every figure into ``out_dir``; per-episode figures use random step ``figure_k``."""
    plt = require_matplotlib()
    drawers = (_steps, _rewards, _cumulative_collisions, _collisions, _collisions_vs_k)
    paths = []
    for name, draw in zip(FIGURE_FILES, drawers):
        figure = draw(plt, grid, figure_k)
        path = out_dir / name
        figure.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(figure)
        paths.append(path)
    return paths


def _per_episode_mean(grid: ResultGrid, algo: str, k: int, values: np.ndarray) -> np.ndarray:
    """The mean over seeds, per episode, of a (runs, episodes) metric."""
    return values[grid.rows(algo, k)].mean(axis=0)


def _panels(plt, grid: ResultGrid, title: str):
    algos = grid.algos
    figure, axes = plt.subplots(1, len(algos), figsize=(6 * len(algos), 4), sharey=True, squeeze=False)
    figure.suptitle(title)
    return figure, dict(zip(algos, axes[0]))


def _seeds_note(grid: ResultGrid) -> str:
    return f"mean over {len(grid.seeds)} seeds"


def _steps(plt, grid: ResultGrid, k: int):
    """Figs. 5 and 6: steps per episode and the minimal number of steps."""
    figure, axes = _panels(plt, grid, f"Steps per episode, random step k = {k} ({_seeds_note(grid)})")
    m = grid.metrics
    episodes = np.arange(1, m.steps.shape[1] + 1)
    for algo, ax in axes.items():
        ax.plot(episodes, _per_episode_mean(grid, algo, k, m.steps), color=ALGO_COLOURS[algo],
                lw=0.8, label=f"{ALGO_LABELS[algo]} steps")
        ax.plot(episodes, _per_episode_mean(grid, algo, k, m.shortest), color="black", lw=0.8,
                alpha=0.7, label="minimal steps")
        ax.set(title=ALGO_LABELS[algo], xlabel="episode", ylabel="steps")
        ax.legend()
    return figure


def _rewards(plt, grid: ResultGrid, k: int):
    """Figs. 7 and 8: rewards per episode, and the destination-seeking reward summed over learning."""
    figure, (total_ax, ds_ax, cumulative_ax) = plt.subplots(1, 3, figsize=(16, 4))
    figure.suptitle(f"Rewards, k = {k} ({_seeds_note(grid)})")
    m = grid.metrics
    episodes = np.arange(1, m.steps.shape[1] + 1)
    for algo in grid.algos:
        ds = _per_episode_mean(grid, algo, k, m.reward_ds)
        ca = _per_episode_mean(grid, algo, k, m.reward_ca)
        style = dict(color=ALGO_COLOURS[algo], label=ALGO_LABELS[algo])
        total_ax.plot(episodes, ds + ca, lw=0.8, **style)
        ds_ax.plot(episodes, ds, lw=0.8, **style)
        cumulative_ax.plot(episodes, np.cumsum(ds), **style)
    total_ax.set(title="sum of rewards per episode (DS + CA)", xlabel="episode", ylabel="reward")
    ds_ax.set(title="destination-seeking reward per episode", xlabel="episode")
    cumulative_ax.set(title="destination-seeking reward, cumulative", xlabel="episode")
    for ax in (total_ax, ds_ax, cumulative_ax):
        ax.legend()
    return figure


def _cumulative_collisions(plt, grid: ResultGrid, k: int):
    """Figs. 9 and 10: the cumulative number of collisions, both algorithms on one axis."""
    figure, ax = plt.subplots(figsize=(7, 4))
    m = grid.metrics
    episodes = np.arange(1, m.steps.shape[1] + 1)
    for algo in grid.algos:
        cumulative = np.cumsum(m.collisions[grid.rows(algo, k)], axis=1)
        ax.plot(episodes, cumulative.mean(axis=0), color=ALGO_COLOURS[algo], label=ALGO_LABELS[algo])
        ax.fill_between(episodes, cumulative.min(axis=0), cumulative.max(axis=0),
                        color=ALGO_COLOURS[algo], alpha=0.15)
    ax.set(title=f"Cumulative collisions, k = {k} ({_seeds_note(grid)}, band: min-max)",
           xlabel="episode", ylabel="collisions")
    ax.legend()
    return figure


def _collisions(plt, grid: ResultGrid, k: int):
    """Figs. 11 and 12: collisions per episode."""
    figure, axes = _panels(plt, grid, f"Collisions per episode, k = {k} ({_seeds_note(grid)})")
    m = grid.metrics
    episodes = np.arange(1, m.steps.shape[1] + 1)
    for algo, ax in axes.items():
        per_episode = _per_episode_mean(grid, algo, k, m.collisions)
        ax.plot(episodes, per_episode, color=ALGO_COLOURS[algo], lw=0.8)
        ax.set(title=ALGO_LABELS[algo], xlabel="episode", ylabel="collisions")
    return figure


def _collisions_vs_k(plt, grid: ResultGrid, k: int):
    """Fig. 13: total collisions against the random step, with 95 % intervals, beside the paper's."""
    rows = table1_rows(grid)
    ks = [int(row["random_step"]) for row in rows]
    figure, ax = plt.subplots(figsize=(7, 4))
    for algo in grid.algos:
        means = np.array([row[f"{algo}_collisions"] for row in rows])
        low = np.array([row[f"{algo}_ci_low"] for row in rows])
        high = np.array([row[f"{algo}_ci_high"] for row in rows])
        errors = np.nan_to_num(np.stack([means - low, high - means]))
        ax.errorbar(ks, means, yerr=errors, marker="o", capsize=3, color=ALGO_COLOURS[algo],
                    label=f"{ALGO_LABELS[algo]} (this run, 95 % CI)")
        paper_ks = [q for q in ks if q in PAPER_TABLE1]
        column = 0 if algo == "ql" else 1
        ax.plot(paper_ks, [PAPER_TABLE1[q][column] for q in paper_ks], ls="--", marker="x",
                color=ALGO_COLOURS[algo], alpha=0.6, label=f"{ALGO_LABELS[algo]} (paper)")
    ax.set(title=f"Total collisions per run vs random step ({_seeds_note(grid)})",
           xlabel="random step k", ylabel="collisions in all episodes")
    ax.set_xticks(ks)
    ax.legend()
    return figure


SWARM_FIGURES = {"arrival": ("swarm_arrival.png", "Share of agents on their goal at the episode's end"),
                 "steps_ratio": ("swarm_steps_ratio.png",
                                 "Steps before arriving over the shortest path"),
                 "collisions": ("swarm_collisions.png", "Collisions per episode")}
"""The swarm experiment's learning curves: one figure per metric, one line per variant."""


def write_swarm_figures(out_dir: Path, curves: dict[str, dict[str, np.ndarray]],
                        seeds: int, smoothing: int) -> list[Path]:
    """Draw the swarm experiment's learning curves (``experiment.swarm_experiment.curves``)."""
    plt = require_matplotlib()
    paths = []
    for metric, (name, title) in SWARM_FIGURES.items():
        figure, axis = plt.subplots(figsize=(9, 4.5))
        for variant, values in curves[metric].items():
            axis.plot(np.arange(values.size), values, label=variant, linewidth=1.4)
        axis.set_title(f"{title} (mean over {seeds} seeds, running mean of {smoothing})")
        axis.set_xlabel("episode")
        if metric == "steps_ratio":
            axis.set_yscale("log")
        axis.grid(alpha=0.3)
        axis.legend(ncol=3, fontsize=8)
        path = out_dir / name
        figure.savefig(path, dpi=110, bbox_inches="tight")
        plt.close(figure)
        paths.append(path)
    return paths
