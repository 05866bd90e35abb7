"""The maps benchmark: the field's protocol (POGEMA's) on the swarm simulator, and its table.

For every seed (a policy of its own, on maps of its own):

1. **Training.** Each learning variant learns on ``train_maps`` random maps (17 to 21 cells a side,
   20 % walls, from the training map seeds), ``train_episodes`` episodes on each, its tables
   carried from one map to the next (its known map is the new map's: it starts knowing no wall).
2. **Frozen play.** The learned tables are played frozen (``SwarmConfig.frozen``: no learning, no
   random step) on ``test_maps`` held-out maps of each family (random; mazes 17 to 21 a side; the
   46 x 33 warehouse, whose held-out instances are new starts and goals), at each agent count, each
   map for ``instances`` episodes, the agent forgetting the map's walls before each. The oracle
   (a reference planner, PIBT) plays the same instances. Every variant plays one on-target rule
   (``on_target``: the paper's ``park``, or ``step-aside``, the field's).
3. **From scratch.** The paper's setting: each variant and the oracle learn on an unseen random
   map (the seed's first test map) for ``scratch_episodes`` episodes.

The suite ``pogema`` plays, in step 2, POGEMA's own instances instead (``experiment.pogema``);
with ``tasks`` lifelong, its lifelong instances (``experiment.pogema_lifelong``), scored by
throughput (training stays one-shot, on our maps).
Without learners (``learners=()``) the oracle plays alone and nothing is trained.

Map seeds: training map ``k`` of seed ``s`` is ``TRAIN_MAP_BASE + s * train_maps + k``, held-out
map ``j`` is ``TEST_MAP_BASE + s * test_maps + j``: disjoint while ``s * train_maps + k`` stays
below ``TEST_MAP_BASE``. A map is the generator spec of ``world.terrain`` (``random:19x19:0.2:SEED``,
``maze:19x19:SEED``, ``warehouse``), its side drawn from the map seed's own stream, and a run on it
has the map seed as its seed: ``launch/swarm.py --map <spec> --seed <map seed> --agents N
--max-steps 128 --preset <variant>`` plays its first episode from scratch.

Every episode played is a row of ``maps_episodes.csv`` (written as it is played); the table
(``maps_table.csv``, ``maps_table.md``) reads them: per seed the mean over its instances, then over
seeds the mean and its 95 % t interval (``experiment.stats``).
"""

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nnql_swarm.experiment.stats import mean_interval
from nnql_swarm.protocol.config import PRESETS, TASKS, SwarmConfig
from nnql_swarm.world.terrain import WAREHOUSE_SIZE, generated
from nnql_swarm.world.pogema_instances import FAMILIES as POGEMA_FAMILIES
from nnql_swarm.protocol.seeding import MAP_STREAM, stream_rng
from nnql_swarm.sim.runs import Batch, Episodes, swarm_world
from nnql_swarm.world.engine import EPISODE_FIELDS

FAMILIES = ("random", "maze", "warehouse")
SIDES = (17, 21)
"""The smallest and largest side of a random map or a maze (POGEMA's)."""
DENSITY = 0.2
"""The share of walls of a random map (POGEMA's)."""
MAX_STEPS = 128
"""The step limit of an episode (POGEMA's)."""
TRAIN_MAP_BASE, TEST_MAP_BASE = 0, 1_000_000
REFERENCE = "oracle"
BASELINE = "ql"
"""The reference planner the costs are read against, and the paper's QL, whose collisions the
others' are read against."""

ROW_KEYS = ("phase", "seed", "family", "map", "agents", "variant", "instance")
EPISODE_COLUMNS = ROW_KEYS + EPISODE_FIELDS
"""The columns of ``maps_episodes.csv``: where the episode was played, then the swarm's row."""

TABLE_FILES = ("maps_table.csv", "maps_table.md")
METRICS = ("isr", "csr", "soc", "soc_vs_oracle", "soc_vs_lb", "makespan", "collisions",
           "collisions_vs_ql_pct", "steps_ratio")
"""``soc_vs_lb``: the sum of costs over its lower bound (the sum of the shortest paths), the mean
over the instances where every agent arrived (the field's figure)."""
LIFELONG_METRICS = ("throughput", "throughput_vs_oracle", "goals", "collisions")
"""A lifelong suite's metrics: goals reached a step, its paired difference against the oracle's
on the same instances (ours minus the oracle's), goals reached, collisions."""
SUITES = ("project", "pogema")
"""Where frozen play happens: held-out maps of our generators, or POGEMA's published
instances."""


@dataclass(frozen=True)
class MapsBenchmark:
    """What the benchmark plays (see the module docstring)."""

    seeds: int = 5
    seed_base: int = 0
    learners: tuple[str, ...] = ("path-nnql", BASELINE)
    train_maps: int = 8
    train_episodes: int = 50
    train_agents: int = 16
    test_maps: int = 4
    instances: int = 4
    agents: tuple[int, ...] = (8, 32, 64)
    families: tuple[str, ...] = FAMILIES
    scratch_episodes: int = 300
    scratch_agents: tuple[int, ...] = (8, 32)
    max_steps: int = MAX_STEPS
    on_target: str = "park"
    suite: str = "project"
    tasks: str = SwarmConfig.tasks
    presets: dict = field(default_factory=lambda: dict(PRESETS), compare=False)

    @property
    def seed_list(self) -> list[int]:
        return list(range(self.seed_base, self.seed_base + self.seeds))

    @property
    def variants(self) -> tuple[str, ...]:
        return (*self.learners, REFERENCE)

    def agent_counts(self, family: str) -> tuple[int, ...]:
        """The agent counts of frozen play on a family: ``agents``, or, left empty on POGEMA's
        instances, the counts of the family's published tables."""
        if self.suite == "pogema" and not self.agents:
            family_ = POGEMA_FAMILIES[family]
            return family_.lifelong_agents if self.lifelong else family_.agents
        return self.agents

    @property
    def lifelong(self) -> bool:
        return self.tasks == "lifelong"

    @property
    def metrics(self) -> tuple[str, ...]:
        """The table's metrics: the field's one-shot ones, or a lifelong run's."""
        return LIFELONG_METRICS if self.lifelong else METRICS

    def frozen_episodes(self) -> int:
        """Episodes a variant plays frozen, each seed."""
        if self.suite == "pogema":
            return sum(len(self.agent_counts(f)) * self.instances for f in self.families)
        return len(self.families) * self.test_maps * len(self.agents) * self.instances

    def train_map_seeds(self, seed: int) -> list[int]:
        return [TRAIN_MAP_BASE + seed * self.train_maps + k for k in range(self.train_maps)]

    def test_map_seeds(self, seed: int) -> list[int]:
        return [TEST_MAP_BASE + seed * self.test_maps + j for j in range(self.test_maps)]

    def check(self) -> None:
        """Refuse a benchmark whose training and held-out map seeds could meet, or an unknown
        variant (ValueError)."""
        last = (self.seed_base + self.seeds) * self.train_maps
        if last > TEST_MAP_BASE:
            raise ValueError(f"training map seeds would reach the held-out ones ({TEST_MAP_BASE}):"
                             f" fewer seeds or training maps")
        for variant in self.learners:
            if variant not in self.presets or variant == REFERENCE:
                raise ValueError(f"--learners: {variant!r} is not a learning preset")
        if self.tasks not in TASKS:
            raise ValueError(f"--tasks: {self.tasks!r} is not one of {', '.join(TASKS)}")
        if self.lifelong and self.suite != "pogema":
            raise ValueError("--tasks lifelong plays POGEMA's lifelong instances: add --suite "
                             "pogema")
        if self.suite == "project":
            for family in self.families:
                if family not in FAMILIES:
                    raise ValueError(f"--families: {family!r} is POGEMA's (--suite pogema); "
                                     f"ours are {', '.join(FAMILIES)}")


def swarm_config(bench: MapsBenchmark, variant: str, name: str, rows: tuple[str, ...], seed: int,
                 agents: int, episodes: int, frozen: bool, scenario: tuple = (),
                 max_steps: int | None = None, tasks: str = "one-shot",
                 goal_lists: tuple = ()) -> SwarmConfig:
    """A run of ``variant`` on the map ``rows`` (the starts and goals of ``scenario`` if given,
    else drawn from ``seed``; lifelong ``tasks``: the goals of ``goal_lists`` next, then drawn);
    the oracle never frozen."""
    return SwarmConfig(run_id=f"m{seed}", n_agents=agents, episodes=episodes,
                       max_steps=max_steps or bench.max_steps or MAX_STEPS, width=len(rows[0]),
                       height=len(rows), seed=seed, map_name=name, map_rows=rows,
                       scenario=scenario, on_target=bench.on_target, tasks=tasks,
                       goal_lists=goal_lists,
                       frozen=frozen and variant != REFERENCE, **bench.presets[variant])


def map_spec(family: str, map_seed: int) -> str:
    """The generator spec of a map of a family (``world.terrain.generated``)."""
    if family == "warehouse":
        return f"warehouse:{WAREHOUSE_SIZE[0]}x{WAREHOUSE_SIZE[1]}"
    side = int(stream_rng(map_seed, MAP_STREAM, 1).integers(SIDES[0], SIDES[1] + 1))
    if family == "random":
        return f"random:{side}x{side}:{DENSITY}:{map_seed}"
    return f"maze:{side}x{side}:{map_seed}"


def run_config(bench: MapsBenchmark, variant: str, spec: str, map_seed: int, agents: int,
               episodes: int, frozen: bool) -> SwarmConfig:
    rows = generated(spec, map_seed)
    assert rows is not None  # a generator's spec always gives rows
    return swarm_config(bench, variant, spec, rows, map_seed, agents, episodes, frozen)


Tables = dict[str, tuple[np.ndarray, np.ndarray]]
"""A learned policy per variant: its Q_DS and Q_CA tables (one, or one per training agent)."""


def learned_tables(batch: Batch, run: int) -> tuple[np.ndarray, np.ndarray]:
    """A run's tables: the swarm's one table if shared, else every agent's."""
    count = 1 if batch.runs[run].shared else batch.world.learners
    return batch.q_ds[run, :count].copy(), batch.q_ca[run, :count].copy()


class Recorder:
    """Appends every episode played to ``maps_episodes.csv``, each row flushed as it is written
    (an interrupted benchmark keeps every episode it played); keeps them for the table."""

    def __init__(self, path: Path | None) -> None:
        self.rows: list[dict] = []
        self._file = open(path, "w", newline="") if path is not None else None
        if self._file is not None:
            self._csv = csv.DictWriter(self._file, fieldnames=EPISODE_COLUMNS)
            self._csv.writeheader()
            self._file.flush()

    def add(self, keys: dict, variants: tuple[str, ...], episodes: Episodes, batch: Batch,
            episode: int) -> None:
        """Episode ``episode`` of every run of ``batch`` (run ``i`` plays ``variants[i]``)."""
        for run, config in enumerate(batch.runs):
            row = {**keys, "variant": variants[run],
                   **episodes.swarm_row(run, episode, config.n_agents)}
            self.rows.append(row)
            if self._file is not None:
                self._csv.writerow(row)
        if self._file is not None:
            self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()


def train(bench: MapsBenchmark, seed: int, recorder: Recorder, on_episode=None) -> Tables:
    """Every learner's policy after the seed's training maps."""
    tables: Tables = {}
    for k, map_seed in enumerate(bench.train_map_seeds(seed) if bench.learners else []):
        spec = map_spec("random", map_seed)
        configs = [run_config(bench, v, spec, map_seed, bench.train_agents, bench.train_episodes,
                              frozen=False) for v in bench.learners]
        batch = Batch(swarm_world(configs[0]), configs)
        for run, variant in enumerate(bench.learners):
            if variant in tables:
                batch.load_tables(run, *tables[variant])
        results = Episodes(len(configs), bench.train_episodes)
        keys = {"phase": "train", "seed": seed, "family": "random", "map": spec,
                "agents": bench.train_agents}

        def played(e, b, keys=keys, results=results, k=k):
            recorder.add({**keys, "instance": k * bench.train_episodes + e}, bench.learners,
                         results, b, e)
            if on_episode is not None:
                on_episode(len(b.runs))

        batch.play(bench.train_episodes, results, on_episode=played)
        tables = {v: learned_tables(batch, run) for run, v in enumerate(bench.learners)}
    return tables


def play_frozen(bench: MapsBenchmark, tables: Tables, spec: str, map_seed: int, agents: int,
                recorder: Recorder, keys: dict, on_episode=None) -> Batch:
    """Every learner's policy, frozen, and the oracle on one held-out map, ``instances``
    episodes, every agent forgetting the map's walls before each."""
    configs = [run_config(bench, v, spec, map_seed, agents, bench.instances, frozen=True)
               for v in bench.variants]
    return play_configs(bench, tables, configs, bench.instances, recorder, keys, on_episode)


def play_configs(bench: MapsBenchmark, tables: Tables, configs: list[SwarmConfig], episodes: int,
                 recorder: Recorder, keys: dict, on_episode=None, first: int = 0) -> Batch:
    """``configs`` (one per variant, on one map) played frozen for ``episodes`` episodes, every
    agent forgetting the map's walls before each; episode ``e`` recorded as instance
    ``first + e``."""
    batch = Batch(swarm_world(configs[0]), configs)
    for run, variant in enumerate(bench.learners):
        batch.load_tables(run, *tables[variant])
    results = Episodes(len(configs), episodes)
    for episode in range(episodes):
        batch.forget_maps()
        batch.play(1, results)
        recorder.add({**keys, "instance": first + episode}, bench.variants, results, batch,
                     episode)
        if on_episode is not None:
            on_episode(len(configs))
    return batch


def scratch(bench: MapsBenchmark, seed: int, agents: int, recorder: Recorder,
            on_episode=None) -> None:
    """Every variant learning from scratch on the seed's first held-out random map."""
    map_seed = bench.test_map_seeds(seed)[0]
    spec = map_spec("random", map_seed)
    configs = [run_config(bench, v, spec, map_seed, agents, bench.scratch_episodes, frozen=False)
               for v in bench.variants]
    batch = Batch(swarm_world(configs[0]), configs)
    results = Episodes(len(configs), bench.scratch_episodes)
    keys = {"phase": "scratch", "seed": seed, "family": "random", "map": spec, "agents": agents}

    def played(e, b):
        recorder.add({**keys, "instance": e}, bench.variants, results, b, e)
        if on_episode is not None:
            on_episode(len(b.runs))

    batch.play(bench.scratch_episodes, results, on_episode=played)


def episodes_total(bench: MapsBenchmark) -> int:
    """Run-episodes the benchmark plays (the progress bar's total)."""
    per_seed = (len(bench.learners) * bench.train_maps * bench.train_episodes
                + len(bench.variants) * (bench.frozen_episodes()
                                         + len(bench.scratch_agents) * bench.scratch_episodes))
    return bench.seeds * per_seed


def play_held_out(bench: MapsBenchmark, tables: Tables, seed: int, recorder: Recorder,
                  on_episode=None) -> None:
    """Frozen play of a seed's policies on its held-out maps of every family."""
    for family in bench.families:
        for map_seed in bench.test_map_seeds(seed):
            spec = map_spec(family, map_seed)
            for agents in bench.agents:
                keys = {"phase": "frozen", "seed": seed, "family": family, "map": spec,
                        "agents": agents}
                play_frozen(bench, tables, spec, map_seed, agents, recorder, keys, on_episode)


def run_benchmark(bench: MapsBenchmark, recorder: Recorder, on_episode=None,
                  policies: Path | None = None, frozen_play=play_held_out,
                  from_scratch=scratch) -> None:
    """Play the whole benchmark, seed by seed, every episode into ``recorder`` (and each seed's
    learned tables into ``policies``, ``<variant>-s<seed>.npz``, if given); ``frozen_play(bench,
    tables, seed, recorder, on_episode)`` plays step 2 (the suite's), ``from_scratch(bench, seed,
    agents, recorder, on_episode)`` step 3."""
    for seed in bench.seed_list:
        tables = train(bench, seed, recorder, on_episode)
        if policies is not None and tables:
            policies.mkdir(parents=True, exist_ok=True)
            for variant, (q_ds, q_ca) in tables.items():
                np.savez_compressed(policies / f"{variant}-s{seed}.npz", q_ds=q_ds, q_ca=q_ca)
        frozen_play(bench, tables, seed, recorder, on_episode)
        for agents in bench.scratch_agents:
            from_scratch(bench, seed, agents, recorder, on_episode)


def scratch_window(bench: MapsBenchmark) -> tuple[int, int]:
    """The episodes the from-scratch rows read: the last fifth, at most the last 50."""
    last = min(50, max(1, bench.scratch_episodes // 5))
    return bench.scratch_episodes - last, bench.scratch_episodes


def table_rows(bench: MapsBenchmark, rows: list[dict]) -> list[dict]:
    """One row per (phase, family, agents, variant): each metric's mean over seeds (each seed's
    value the mean over its instances) and its 95 % interval (see the module docstring)."""
    w0, w1 = scratch_window(bench)
    groups: dict[tuple, dict[int, list[dict]]] = {}
    for row in rows:
        phase = row["phase"]
        if phase == "train" or (phase == "scratch" and not w0 <= int(row["instance"]) < w1):
            continue
        key = (phase, row["family"], int(row["agents"]), row["variant"])
        groups.setdefault(key, {}).setdefault(int(row["seed"]), []).append(row)
    out = []
    for (phase, family, agents, variant), by_seed in groups.items():
        reference = groups.get((phase, family, agents, REFERENCE), {})
        baseline = groups.get((phase, family, agents, BASELINE), {})
        per_seed: dict[str, list[float]] = {m: [] for m in bench.metrics}
        for seed, episodes in sorted(by_seed.items()):
            values = seed_values(episodes, reference.get(seed), baseline.get(seed))
            for metric in bench.metrics:
                per_seed[metric].append(values[metric])
        row = {"phase": phase, "family": family, "agents": agents, "variant": variant,
               "seeds": len(by_seed), "episodes": sum(len(e) for e in by_seed.values())}
        for metric in bench.metrics:
            column = np.array(per_seed[metric], dtype=float)
            interval = mean_interval(column[np.isfinite(column)])
            row[metric], row[f"{metric}_low"], row[f"{metric}_high"] = (
                interval.mean, interval.low, interval.high)
        out.append(row)
    order = {"frozen": 0, "scratch": 1}
    families = (*bench.families, *FAMILIES)
    out.sort(key=lambda r: (order[r["phase"]], families.index(r["family"]), r["agents"],
                            bench.variants.index(r["variant"])))
    return out


def seed_values(episodes: list[dict], reference: list[dict] | None,
                baseline: list[dict] | None) -> dict[str, float]:
    """One seed's metrics over its instances; the ratios against the oracle's and QL's same
    instances (NaN where they were not played or are 0), and the throughput's difference from
    the oracle's (NaN where it was not played)."""
    def total(rows, column):
        return sum(float(r[column]) for r in rows)

    count = len(episodes)
    values = {"isr": total(episodes, "isr") / count, "csr": total(episodes, "csr") / count,
              "soc": total(episodes, "soc") / count, "makespan": total(episodes, "makespan") / count,
              "collisions": total(episodes, "collisions") / count,
              "steps_ratio": total(episodes, "agent_steps") / max(total(episodes, "shortest_sum"), 1)}
    if "throughput" in episodes[0]:  # rows of a run before lifelong tasks have none
        values["goals"] = total(episodes, "goals") / count
        values["throughput"] = total(episodes, "throughput") / count
        values["throughput_vs_oracle"] = (values["throughput"]
                                          - total(reference, "throughput") / len(reference)
                                          if reference else math.nan)
    values["soc_vs_oracle"] = (total(episodes, "soc") / total(reference, "soc")
                               if reference and total(reference, "soc") > 0 else math.nan)
    solved = [float(r["soc"]) / max(float(r["shortest_sum"]), 1.0) for r in episodes
              if int(r["csr"]) == 1]
    values["soc_vs_lb"] = sum(solved) / len(solved) if solved else math.nan
    base = total(baseline, "collisions") if baseline else 0.0
    values["collisions_vs_ql_pct"] = (100.0 * total(episodes, "collisions") / base
                                      if base > 0 else math.nan)
    return values


def write_tables(out: Path, bench: MapsBenchmark, rows: list[dict], elapsed_s: float,
                 text: str | None = None) -> None:
    """``maps_table.csv`` and ``maps_table.md`` (``text``, else :func:`markdown`'s), each
    written whole or not at all."""
    columns = list(rows[0]) if rows else ["phase"]
    csv_path, md_path = out / "maps_table.csv", out / "maps_table.md"
    partial = csv_path.with_suffix(".csv.partial")
    with open(partial, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=columns)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: _cell(v) for k, v in row.items()})
    partial.replace(csv_path)
    partial = md_path.with_suffix(".md.partial")
    partial.write_text(markdown(bench, rows, elapsed_s) if text is None else text)
    partial.replace(md_path)


def markdown(bench: MapsBenchmark, rows: list[dict], elapsed_s: float) -> str:
    w0, w1 = scratch_window(bench)
    lines = [f"# The maps benchmark (POGEMA's protocol): seeds {bench.seed_base}-"
             f"{bench.seed_base + bench.seeds - 1}, {bench.max_steps} steps an episode", "",
             f"Trained on {bench.train_maps} random maps x {bench.train_episodes} episodes, "
             f"{bench.train_agents} agents; frozen on {bench.test_maps} held-out maps a family x "
             f"{bench.instances} instances; from scratch: {bench.scratch_episodes} episodes on an "
             f"unseen random map, episodes {w0}-{w1 - 1} read. Each cell: the mean over seeds "
             f"[95 % t interval]; SoC / oracle and collisions / QL on the same instances. "
             f"{elapsed_s:.0f} s.", "",
             "| phase | family | agents | variant | ISR | CSR | SoC / oracle | makespan | "
             "collisions / episode | collisions % of QL | steps ratio |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        cells = [with_interval(row, m, digits)
                 for m, digits in (("isr", 3), ("csr", 2), ("soc_vs_oracle", 2), ("makespan", 1),
                                   ("collisions", 2), ("collisions_vs_ql_pct", 2),
                                   ("steps_ratio", 2))]
        lines.append(f"| {row['phase']} | {row['family']} | {row['agents']} | {row['variant']} | "
                     + " | ".join(cells) + " |")
    lines += ["", "ISR: the share of agents on their goal at the episode's end; CSR: 1 if all are; "
              "SoC: the sum over agents of the step each last arrived (the episode's steps for one "
              "that did not); makespan: the largest (docs/swarm.md, \"The field's metrics\")."]
    return "\n".join(lines) + "\n"


def learning_curves(bench: MapsBenchmark, rows: list[dict],
                    smoothing: int = 5) -> dict[str, dict[str, np.ndarray]]:
    """Per metric (ISR, CSR, collisions; learning from scratch lifelong: throughput, collisions)
    and per curve (``train-<variant>``, ``scratch-<agents>-<variant>``), the mean over seeds of
    each episode, as a running mean."""
    one_shot: tuple[str, ...] = ("isr", "csr", "collisions")
    scratch_metrics = ("throughput", "collisions") if bench.lifelong else one_shot
    series: dict[tuple[str, str], dict[int, list[float]]] = {}
    for row in rows:
        if row["phase"] == "train":
            name, metrics = f"train-{row['variant']}", one_shot
        elif row["phase"] == "scratch":
            name, metrics = f"scratch-{row['agents']}-{row['variant']}", scratch_metrics
        else:
            continue
        for metric in metrics:
            series.setdefault((metric, name), {}).setdefault(int(row["instance"]), []).append(
                float(row[metric]))
    curves: dict[str, dict[str, np.ndarray]] = {
        metric: {} for metric in dict.fromkeys(one_shot + scratch_metrics)}
    for (metric, name), by_episode in series.items():
        values = np.array([np.mean(by_episode[e]) for e in sorted(by_episode)])
        cumulative = np.cumsum(np.insert(values, 0, 0.0))
        counts = np.minimum(np.arange(1, values.size + 1), smoothing)
        curves[metric][name] = (cumulative[1:] - cumulative[np.arange(values.size) + 1 - counts]
                                ) / counts
    return curves


def write_curves(path: Path, curves: dict[str, dict[str, np.ndarray]]) -> None:
    """The learning curves as a long csv: metric, curve, episode, value."""
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["metric", "curve", "episode", "value"])
        for metric, by_name in curves.items():
            for name, values in sorted(by_name.items()):
                for episode, value in enumerate(values.tolist()):
                    writer.writerow([metric, name, episode, f"{value:.4f}"])


def _cell(value):
    if isinstance(value, float):
        return "" if math.isnan(value) else f"{value:.4f}"
    return value


def with_interval(row: dict, metric: str, digits: int) -> str:
    """A table row's metric as ``mean [low, high]`` (the mean alone where one seed, blank where
    none)."""
    mean, low, high = row[metric], row[f"{metric}_low"], row[f"{metric}_high"]
    if math.isnan(mean):
        return ""
    text = f"{mean:.{digits}f}"
    return text if math.isnan(low) else f"{text} [{low:.{digits}f}, {high:.{digits}f}]"
