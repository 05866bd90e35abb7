"""The swarm experiment: every learning preset over seeds, on the swarm simulator, and its table.

Each variant is a preset of ``protocol.config.PRESETS`` (the paper's QL and nnQL, the best options
found, the shield, n = 2, DAQL, the oracle) played by ``sim.episode`` for every seed: 8 learning
agents by default, on the swarm's world (11 x 11, swaps counted), exactly the run
``launch/swarm.py --preset <variant> --seed <seed>`` plays. What each run leaves is the swarm's
own ``episodes.csv`` (``runs/<variant>-s<seed>/``), so any run can be checked against the
distributed swarm; the table reads those rows:

- ``arrival_A_B``: the share of agents on their goal at the episode's end, over episodes A..B-1,
  mean over seeds (the windows are the 2nd and the 5th fifth of the run: 100-200 and 400-500 of
  500 episodes);
- ``steps_ratio_A_B``: the ticks agents spent before arriving (up to the episode's end for those
  that did not), over the sum of their shortest paths (around the walls, if any), late in the run;
- ``collisions``: a run's total (every agent in a collision counts one per step), mean over
  seeds, with its 95 % t interval;
- ``decrease_vs_ql_pct``: the decrease against the QL row with the same options (``vs``), with the
  paired difference's 95 % interval over the seeds;
- ``csr_A_B``, ``isr_A_B``, ``soc_A_B``, ``makespan_A_B``: the field's metrics (POGEMA's,
  ``world.rules.field_columns``) late in the run, mean over episodes and seeds.
"""

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nnql_swarm.experiment.stats import mean_interval
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, Episodes, swarm_world, threads
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.rules import FIELD_COLUMNS, field_columns

VARIANTS = ("ql", "nnql", "best-ql", "best-nnql", "shield-ql", "shield-nnql", "path-nnql",
            "nnql-n2", "daql", "oracle")
"""The table's rows, in order."""

COMPARED_WITH = {"nnql": "ql", "best-nnql": "best-ql", "shield-nnql": "shield-ql",
                 "nnql-n2": "best-ql", "daql": "best-ql", "shield-ql": "best-ql",
                 "best-ql": "ql", "oracle": "best-ql"}
"""The QL row each row's collisions are compared with: the one with the same options."""

TABLE_FILES = ("swarm_table.csv", "swarm_table.md")

ABLATED = ("interaction_radius", "optimistic", "shared", "still_terminal", "alpha")
"""The options of ``best-nnql`` beyond the paper, each of which the ablation takes back."""


def ablation_presets() -> dict[str, dict]:
    """``best-nnql`` with each of its options beyond the paper taken back in turn (to the
    paper's value), with the paper's nnQL reading instead of the direction-aware one, with a
    state block for known neighbours, and with the ``meet`` wait rule; the swarm's default
    (``shield-nnql``: radius 2, the ``meet`` rule) as it is, with the ``reach`` rule, and as the
    full chain (the paper's radius, 10, and its ``reach`` rule); the QL and nnQL rows they are
    read against."""
    best, paper, shield = PRESETS["best-nnql"], PRESETS["nnql"], PRESETS["shield-nnql"]
    presets = {name: PRESETS[name] for name in ("ql", "nnql", "best-ql", "best-nnql")}
    for option in ABLATED:
        presets[f"best-nnql-paper-{option.replace('_', '-')}"] = {**best, option: paper[option]}
    presets["best-nnql-plain-nnql"] = {**best, "algo": "nnql"}
    presets["best-nnql-known-state"] = {**best, "known_state": True}
    presets["best-nnql-wait-rule-meet"] = {**best, "wait_rule": "meet"}
    presets["shield-nnql"] = shield
    presets["shield-nnql-paper-wait-rule"] = {**shield, "wait_rule": paper["wait_rule"]}
    presets["shield-nnql-full-chain"] = {**shield, "wait_rule": paper["wait_rule"],
                                         "interaction_radius": paper["interaction_radius"]}
    return presets


def walls_presets() -> dict[str, dict]:
    """The default (``path-nnql``) with each of its options beyond ``shield-nnql`` taken back in
    turn, or read another way, beside ``shield-nnql`` (all taken back) and ``shield-ql``."""
    path, shield = PRESETS["path-nnql"], PRESETS["shield-nnql"]
    return {
        "shield-ql": PRESETS["shield-ql"], "shield-nnql": shield, "path-nnql": path,
        "path-nnql-goal-state": {**path, "ds_state": "goal"},
        "path-nnql-waypoint-state": {**path, "ds_state": "waypoint"},
        "path-nnql-path-reward": {**path, "ds_reward": "path"},
        "path-nnql-euclid-reward": {**path, "ds_reward": "euclid"},
        "path-nnql-no-detour": {**path, "detour": False},
        "path-nnql-beta-05": {**path, "beta": shield["beta"]},
        "path-nnql-beta-07": {**path, "beta": 0.7},
        "path-nnql-no-escape-shield": {**path, "escape_shield": False},
    }


RUN = SwarmConfig()
"""A swarm run's defaults, which the experiment's world takes (its length is its own)."""


@dataclass(frozen=True)
class SwarmExperiment:
    """What the experiment runs: the swarm's world (by default a swarm run's, :data:`RUN`), its
    length, the seeds and the variants."""

    agents: int = RUN.n_agents
    seeds: int = 10
    seed_base: int = 0
    episodes: int = 500
    max_steps: int = RUN.max_steps
    width: int = RUN.width
    height: int = RUN.height
    obstacle_density: float = RUN.obstacle_density
    on_target: str = "park"
    map_name: str = ""
    map_rows: tuple[str, ...] = ()
    scenario: tuple = ()
    """The map every seed plays (``--map``; its starts and goals from ``--scen``), if any."""
    variants: tuple[str, ...] = VARIANTS
    presets: dict[str, dict] = field(default_factory=lambda: dict(PRESETS))

    def config(self, variant: str, seed: int) -> SwarmConfig:
        """The swarm config of one run (the one ``launch/swarm.py --preset`` would resolve)."""
        return SwarmConfig(run_id=run_name(variant, seed), n_agents=self.agents,
                           episodes=self.episodes, max_steps=self.max_steps, width=self.width,
                           height=self.height, seed=seed, obstacle_density=self.obstacle_density,
                           on_target=self.on_target,
                           map_name=self.map_name, map_rows=self.map_rows, scenario=self.scenario,
                           **self.presets[variant])

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seed_base, self.seed_base + self.seeds))

    def windows(self) -> tuple[tuple[int, int], tuple[int, int]]:
        """The early and late windows: the 2nd and the 5th fifth of the run."""
        fifth = self.episodes / 5
        return (round(fifth), round(2 * fifth)), (round(4 * fifth), self.episodes)

    def __hash__(self) -> int:
        return hash((self.agents, self.seeds, self.seed_base, self.episodes, self.variants,
                     self.obstacle_density, self.on_target, self.map_rows, self.scenario))


def run_name(variant: str, seed: int) -> str:
    return f"{variant}-s{seed}"


@dataclass
class SwarmResults:
    """Every run's episodes, by (variant, seed)."""

    experiment: SwarmExperiment
    episodes: Episodes
    runs: list[tuple[str, int]] = field(default_factory=list)

    def rows_of(self, variant: str) -> list[int]:
        return [row for row, (v, _) in enumerate(self.runs) if v == variant]


def run_experiment(experiment: SwarmExperiment, workers: int | None = None,
                   on_episode=None) -> SwarmResults:
    """Play every (variant, seed) in one batch; ``on_episode(e)`` after each episode."""
    runs = [(variant, seed) for variant in experiment.variants for seed in experiment.seed_list]
    configs = [experiment.config(variant, seed) for variant, seed in runs]
    callback = None if on_episode is None else (lambda episode, _batch: on_episode(episode))
    with threads(workers):
        episodes = Batch(swarm_world(configs[0]), configs).play(
            experiment.episodes, on_episode=callback)
    return SwarmResults(experiment, episodes, runs)


def table_rows(results: SwarmResults) -> list[dict]:
    """One row per variant (see the module docstring for the columns)."""
    e, episodes = results.experiment, results.episodes
    (a0, a1), (b0, b1) = e.windows()
    totals = episodes.collisions.sum(axis=1)
    rows = []
    for variant in e.variants:
        at = results.rows_of(variant)
        arrival = episodes.arrived[at] / e.agents
        ratio = (episodes.agent_steps[at, b0:b1].sum(axis=1)
                 / np.maximum(episodes.shortest[at, b0:b1].sum(axis=1), 1))
        collisions = mean_interval(totals[at])
        row = {"variant": variant, "seeds": len(at),
               f"arrival_{a0}_{a1}": float(arrival[:, a0:a1].mean()),
               f"arrival_{b0}_{b1}": float(arrival[:, b0:b1].mean()),
               f"steps_ratio_{b0}_{b1}": float(ratio.mean()),
               "collisions": collisions.mean, "collisions_ci_low": collisions.low,
               "collisions_ci_high": collisions.high}
        base = COMPARED_WITH.get(variant)
        if base in e.variants:
            ql = totals[results.rows_of(base)]
            difference = mean_interval(ql - totals[at])
            row.update(vs=base, decrease_vs_ql_pct=100.0 * (1.0 - collisions.mean / ql.mean())
                       if ql.mean() > 0 else math.nan,
                       difference=difference.mean, difference_ci_low=difference.low,
                       difference_ci_high=difference.high)
        else:
            row.update(vs="", decrease_vs_ql_pct=math.nan, difference=math.nan,
                       difference_ci_low=math.nan, difference_ci_high=math.nan)
        late = [field_columns(int(episodes.on_goal[r, k]), int(episodes.soc[r, k]),
                              int(episodes.makespan[r, k]), e.agents)
                for r in at for k in range(b0, b1)]
        for metric in FIELD_COLUMNS:
            row[f"{metric}_{b0}_{b1}"] = float(np.mean([values[metric] for values in late]))
        rows.append(row)
    return rows


def write_tables(out: Path, results: SwarmResults, rows: list[dict]) -> None:
    """``swarm_table.csv`` and ``swarm_table.md``."""
    columns = list(rows[0])
    with open(out / "swarm_table.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _csv_cell(v) for k, v in row.items()})
    (out / "swarm_table.md").write_text(markdown(results, rows))


def markdown(results: SwarmResults, rows: list[dict]) -> str:
    e = results.experiment
    (a0, a1), (b0, b1) = e.windows()
    head = (f"| variant | arrival {a0}-{a1} | arrival {b0}-{b1} | steps ratio {b0}-{b1} | "
            f"collisions [95 % CI] | vs | decrease % | difference [95 % CI] | CSR {b0}-{b1} | "
            f"SoC {b0}-{b1} | makespan {b0}-{b1} |")
    walls = f", obstacle density {e.obstacle_density}" if e.obstacle_density else ""
    walls += f", map {e.map_name}" if e.map_name else ""
    walls += f", on target {e.on_target}" if e.on_target != "park" else ""
    lines = [f"# The swarm experiment: {e.agents} agents, {e.width} x {e.height}{walls}, swaps "
             f"counted, {e.episodes} episodes, seeds {e.seed_base}-{e.seed_base + e.seeds - 1}", "",
             head, "|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        lines.append(
            f"| {row['variant']} | {row[f'arrival_{a0}_{a1}']:.3f} | {row[f'arrival_{b0}_{b1}']:.3f} "
            f"| {row[f'steps_ratio_{b0}_{b1}']:.2f} | {row['collisions']:.1f} "
            f"{_interval(row['collisions_ci_low'], row['collisions_ci_high'])} | {row['vs']} "
            f"| {_number(row['decrease_vs_ql_pct'], 1)} | {_number(row['difference'], 1)} "
            f"{_interval(row['difference_ci_low'], row['difference_ci_high'])} "
            f"| {row[f'csr_{b0}_{b1}']:.2f} | {row[f'soc_{b0}_{b1}']:.1f} "
            f"| {row[f'makespan_{b0}_{b1}']:.1f} |")
    lines += ["", "Each variant is a set of learning options (a preset of `protocol/config.py` where "
              "it has the name of one); one run of a preset is `python launch/swarm.py --preset "
              f"<variant> --agents {e.agents} --episodes {e.episodes} --seed <seed> "
              + (f"--map {e.map_name}" if e.map_name else f"--grid {e.width}x{e.height}")
              + (f" --obstacle-density {e.obstacle_density}" if e.obstacle_density else "")
              + (f" --on-target {e.on_target}" if e.on_target != "park" else "")
              + " --in-process`, whose `episodes.csv` equals "
              "`runs/<variant>-s<seed>/episodes.csv` here.", ""]
    for variant in e.variants:
        options = ", ".join(f"{k}={v}" for k, v in e.presets[variant].items())
        lines.append(f"- `{variant}`: {options}")
    return "\n".join(lines) + "\n"


def write_runs(out: Path, results: SwarmResults) -> None:
    """Every run's ``config.json`` and ``episodes.csv``, as ``launch/swarm.py`` writes them."""
    for row, (variant, seed) in enumerate(results.runs):
        directory = out / "runs" / run_name(variant, seed)
        directory.mkdir(parents=True, exist_ok=True)
        (directory / "config.json").write_text(
            results.experiment.config(variant, seed).to_json() + "\n")
        path = directory / "episodes.csv"
        path.unlink(missing_ok=True)
        with EpisodeWriter(path, sync=False) as writer:
            for episode in range(results.experiment.episodes):
                writer.write(results.episodes.swarm_row(row, episode, results.experiment.agents),
                             0.0, 0)


def curves(results: SwarmResults, smoothing: int = 10) -> dict[str, dict[str, np.ndarray]]:
    """Per variant, the mean over seeds of each episode's arrival, steps ratio and collisions,
    as a running mean over ``smoothing`` episodes."""
    e, episodes = results.experiment, results.episodes
    out: dict[str, dict[str, np.ndarray]] = {"arrival": {}, "steps_ratio": {}, "collisions": {}}
    for variant in e.variants:
        at = results.rows_of(variant)
        per_episode = {
            "arrival": (episodes.arrived[at] / e.agents).mean(axis=0),
            "steps_ratio": (episodes.agent_steps[at].sum(axis=0)
                            / np.maximum(episodes.shortest[at].sum(axis=0), 1)),
            "collisions": episodes.collisions[at].mean(axis=0),
        }
        for name, values in per_episode.items():
            out[name][variant] = _running_mean(values, smoothing)
    return out


def _running_mean(values: np.ndarray, window: int) -> np.ndarray:
    cumulative = np.cumsum(np.insert(values.astype(float), 0, 0.0))
    counts = np.minimum(np.arange(1, values.size + 1), window)
    return (cumulative[1:] - cumulative[np.arange(values.size) + 1 - counts]) / counts


def _csv_cell(value):
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.4f}"
    return value


def _number(value: float, digits: int) -> str:
    return "" if math.isnan(value) else f"{value:.{digits}f}"


def _interval(low: float, high: float) -> str:
    return "" if math.isnan(low) else f"[{low:.1f}, {high:.1f}]"
