"""The maps benchmark on POGEMA's lifelong instances (``launch/experiment.py maps --suite pogema
--tasks lifelong``): step 2 of ``experiment.maps_benchmark`` played on the published lifelong instances,
scored by throughput (goals reached a step), and its table beside the published figures.

Each seed's policies, trained one-shot on the project's own random maps (step 1, as in the
one-shot suite), and the oracle (PIBT-greedy: priority inheritance with preferences by distance,
no learning) play, frozen, the first ``instances`` of the 128 lifelong instances of each family
(``maps/pogema/<family>/lifelong/*.goals``, ``world.pogema_instances``), each instance once: its map, the
first k agents' starts and goals in turn, then goals drawn from the seed, at the agent counts of
the published lifelong tables (or ``agents``), for the family's lifelong step limit (256; 128 on
the mazes; or ``max_steps``). Learning from scratch (``scratch_agents``): every variant learns
on the first random instance, ``scratch_episodes`` episodes, each the instance again (its listed
goals, then goals drawn from the seed and the episode). A run on one is ``launch/swarm.py --map
maps/pogema/<family>/<map>.map --goals maps/pogema/<family>/lifelong/<instance>.goals --agents k
--tasks lifelong --max-steps 256 --seed <seed> --episodes 1 --in-process``.
"""

import math
from pathlib import Path

from nnql_swarm.experiment.maps_benchmark import (
    REFERENCE, MapsBenchmark, Recorder, Tables, play_configs, scratch_window, swarm_config,
    with_interval,
)
from nnql_swarm.experiment.pogema import check_families, trained
from nnql_swarm.sim.runs import Batch, Episodes, swarm_world
from nnql_swarm.experiment.published import (
    THROUGHPUT, THROUGHPUT_METHODS, THROUGHPUT_SOURCES, figure,
)
from nnql_swarm.world.pogema_instances import FAMILIES, INSTANCES, goals_files, read_lifelong


def steps(bench: MapsBenchmark, family: str) -> int:
    """A lifelong episode's step limit on a family: ``max_steps``, or (0) the family's own."""
    return bench.max_steps or FAMILIES[family].lifelong_steps


def play_lifelong(bench: MapsBenchmark, tables: Tables, seed: int, recorder: Recorder,
                  on_episode=None, directory: Path = INSTANCES) -> None:
    """Frozen play of a seed's policies and the oracle on POGEMA's lifelong instances (the
    module docstring)."""
    for family in bench.families:
        files = goals_files(family, directory)[:bench.instances]
        for agents in bench.agent_counts(family):
            keys = {"phase": "frozen", "seed": seed, "family": family, "agents": agents}
            for index, path in enumerate(files):
                instance = read_lifelong(path, agents)
                configs = [swarm_config(bench, variant, instance.map_name, instance.rows, seed,
                                        agents, 1, True, instance.scenario,
                                        steps(bench, family), "lifelong", instance.goal_lists)
                           for variant in bench.variants]
                play_configs(bench, tables, configs, 1, recorder,
                             {**keys, "map": instance.name}, on_episode, first=index)


def scratch_lifelong(bench: MapsBenchmark, seed: int, agents: int, recorder: Recorder,
                     on_episode=None, directory: Path = INSTANCES) -> None:
    """Every variant learning from scratch on the first random lifelong instance."""
    instance = read_lifelong(goals_files("random", directory)[0], agents)
    configs = [swarm_config(bench, variant, instance.map_name, instance.rows, seed, agents,
                            bench.scratch_episodes, False, instance.scenario,
                            steps(bench, "random"), "lifelong", instance.goal_lists)
               for variant in bench.variants]
    batch = Batch(swarm_world(configs[0]), configs)
    results = Episodes(len(configs), bench.scratch_episodes)
    keys = {"phase": "scratch", "seed": seed, "family": "random", "map": instance.name,
            "agents": agents}

    def played(e, b):
        recorder.add({**keys, "instance": e}, bench.variants, results, b, e)
        if on_episode is not None:
            on_episode(len(b.runs))

    batch.play(bench.scratch_episodes, results, on_episode=played)


def check(bench: MapsBenchmark, directory: Path = INSTANCES) -> None:
    """``experiment.pogema.check_families`` over the lifelong instances (``.goals``), and the
    instance learned on from scratch."""
    check_families(bench, lambda family, agents: read_lifelong(goals_files(family, directory)[0],
                                                               agents))
    if bench.scratch_agents:
        read_lifelong(goals_files("random", directory)[0], max(bench.scratch_agents))


def markdown(bench: MapsBenchmark, rows: list[dict], elapsed_s: float) -> str:
    """The table: our rows, then our throughput beside the published figures, with their
    sources, and each learner's throughput against the oracle's on the same instances."""
    counts = ", ".join(f"{f} {'/'.join(map(str, bench.agent_counts(f)))} agents, "
                       f"{steps(bench, f)} steps" for f in bench.families)
    lines = [f"# The maps benchmark on POGEMA's lifelong instances: seeds {bench.seed_base}-"
             f"{bench.seed_base + bench.seeds - 1}, on target: {bench.on_target}", "",
             trained(bench, "one-shot")
             + f"frozen on the first {bench.instances} of POGEMA's 128 lifelong "
             f"instances a family (maps/pogema/*/lifelong): {counts}. Each cell: the mean over "
             f"seeds [95 % t interval]." + _scratch(bench) + f" {elapsed_s:.0f} s.", "",
             "| phase | family | agents | variant | throughput | throughput - oracle's | goals "
             "| collisions / episode |",
             "|---|---|---:|---|---:|---:|---:|---:|"]
    for row in rows:
        cells = [with_interval(row, m, digits) for m, digits in (
            ("throughput", 2), ("throughput_vs_oracle", 2), ("goals", 1), ("collisions", 2))]
        lines.append(f"| {row['phase']} | {row['family']} | {row['agents']} | {row['variant']} | "
                     + " | ".join(cells) + " |")
    frozen = {(r["family"], r["agents"], r["variant"]): r for r in rows if r["phase"] == "frozen"}
    lines += ["", "## Throughput, beside the published", "",
              "| family | agents | " + " | ".join(bench.variants) + " | "
              + " | ".join(THROUGHPUT_METHODS) + " |",
              "|---|---:|" + "---:|" * (len(bench.variants) + len(THROUGHPUT_METHODS))]
    for family in bench.families:
        for agents in bench.agent_counts(family):
            ours = [with_interval(frozen[family, agents, v], "throughput", 2)
                    if (family, agents, v) in frozen else "" for v in bench.variants]
            theirs = [_published(figure(THROUGHPUT, family, m, agents))
                      for m in THROUGHPUT_METHODS]
            lines.append(f"| {family} | {agents} | " + " | ".join(ours + theirs) + " |")
    if bench.learners:
        lines += ["", f"## Learning against the {REFERENCE} (PIBT-greedy), same instances", "",
                  "Throughput minus the oracle's, paired by instance: the mean over seeds "
                  "[95 % t interval].", "",
                  "| family | agents | " + " | ".join(bench.learners) + " |",
                  "|---|---:|" + "---:|" * len(bench.learners)]
        for family in bench.families:
            for agents in bench.agent_counts(family):
                cells = [with_interval(frozen[family, agents, v], "throughput_vs_oracle", 2)
                         if (family, agents, v) in frozen else "" for v in bench.learners]
                lines.append(f"| {family} | {agents} | " + " | ".join(cells) + " |")
    lines += ["", "Published figures: the mean over all 128 lifelong instances of a family, "
              "POGEMA's on_target 'restart' (a new goal on arrival), its lifelong step limit "
              "(max_episode_steps). Sources: "
              + "; ".join(f"{m}: {THROUGHPUT_SOURCES[m]}" for m in THROUGHPUT_METHODS)
              + " (experiment/published.py).", "",
              "Throughput: goals reached over the episode's steps; goals: goals reached in the "
              "episode (docs/swarm.md, \"Lifelong tasks\")."]
    return "\n".join(lines) + "\n"


def _scratch(bench: MapsBenchmark) -> str:
    if not bench.scratch_agents:
        return ""
    w0, w1 = scratch_window(bench)
    return (f" From scratch: {bench.scratch_episodes} episodes learning on the first random "
            f"instance, episodes {w0}-{w1 - 1} read.")


def _published(value: float | None) -> str:
    return "" if value is None or math.isnan(value) else f"{value:.2f}"
