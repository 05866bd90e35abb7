"""The maps benchmark on POGEMA's own instances (``launch/experiment.py maps --suite pogema``):
step 2 of ``experiment.maps_benchmark`` played on the published instances instead of our held-out maps,
and its table beside the published figures.

Each seed's policies, trained on the project's own random maps (step 1, disjoint from these),
and the oracle play, frozen, the first ``instances`` of the 128 instances of each family
(``maps/pogema/``, ``world.pogema_instances``), each instance once: its map, and the first k lines of its
``.scen`` as the starts and goals of k agents, at the agent counts of the published tables (or
``agents``), for the family's step limit (128; 256 on MovingAI; or ``max_steps``). A run on one
is ``launch/swarm.py --map maps/pogema/<family>/<map>.map --scen
maps/pogema/<family>/<instance>.scen --agents k --max-steps 128 --on-target step-aside
--episodes 1 --in-process``.
"""

from collections.abc import Callable
import math
from pathlib import Path

from nnql_swarm.experiment.maps_benchmark import (
    REFERENCE, MapsBenchmark, Recorder, Tables, play_configs, swarm_config, with_interval,
)
from nnql_swarm.experiment.published import CSR, METHODS, SOC_OVER_LOWER_BOUND, SOURCES, figure
from nnql_swarm.world.pogema_instances import FAMILIES, INSTANCES, read_instance, scen_files


def steps(bench: MapsBenchmark, family: str) -> int:
    """An episode's step limit on a family: ``max_steps``, or (0) the family's own."""
    return bench.max_steps or FAMILIES[family].max_steps


def play_pogema(bench: MapsBenchmark, tables: Tables, seed: int, recorder: Recorder,
                on_episode=None, directory: Path = INSTANCES) -> None:
    """Frozen play of a seed's policies and the oracle on POGEMA's instances (the module
    docstring)."""
    for family in bench.families:
        files = scen_files(family, directory)[:bench.instances]
        for agents in bench.agent_counts(family):
            keys = {"phase": "frozen", "seed": seed, "family": family, "agents": agents}
            for index, scen in enumerate(files):
                instance = read_instance(scen, agents)
                configs = [swarm_config(bench, variant, instance.map_name, instance.rows, seed,
                                        agents, 1, True, instance.tasks, steps(bench, family))
                           for variant in bench.variants]
                play_configs(bench, tables, configs, 1, recorder,
                             {**keys, "map": instance.name}, on_episode, first=index)


def check_families(bench: MapsBenchmark, read_first: Callable[[str, int], object]) -> None:
    """Refuse what cannot be played: a family that is not POGEMA's, more instances than a family
    has (ValueError), an agent count above an instance's (``read_first(family, agents)`` reads
    the family's first instance for that many agents: ValueError; a missing file: MapError)."""
    for family in bench.families:
        if family not in FAMILIES:
            raise ValueError(f"--families: {family!r} is not one of POGEMA's "
                             f"({', '.join(FAMILIES)})")
        if bench.instances > FAMILIES[family].instances:
            raise ValueError(f"--instances: {family} has {FAMILIES[family].instances}")
        read_first(family, max(bench.agent_counts(family)))


def check(bench: MapsBenchmark, directory: Path = INSTANCES) -> None:
    """:func:`check_families` over the one-shot instances (``.scen``)."""
    check_families(bench, lambda family, agents: read_instance(scen_files(family, directory)[0],
                                                               agents))


def markdown(bench: MapsBenchmark, rows: list[dict], elapsed_s: float) -> str:
    """The table: our rows, then our CSR and SoC beside the published figures, with their
    sources."""
    counts = ", ".join(f"{f} {'/'.join(map(str, bench.agent_counts(f)))} agents, "
                       f"{steps(bench, f)} steps" for f in bench.families)
    lines = [f"# The maps benchmark on POGEMA's instances: seeds {bench.seed_base}-"
             f"{bench.seed_base + bench.seeds - 1}, on target: {bench.on_target}", "",
             trained(bench) + f"frozen on the first {bench.instances} of POGEMA's 128 instances "
             f"a family (maps/pogema): {counts}. Each cell: the mean over seeds [95 % t "
             f"interval]; SoC / LB: the sum of costs over the sum of shortest paths, on the "
             f"solved instances. {elapsed_s:.0f} s.", "",
             "| phase | family | agents | variant | ISR | CSR | SoC / LB (solved) | SoC / oracle "
             "| makespan | collisions / episode |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|---:|"]
    for row in rows:
        cells = [with_interval(row, m, digits) for m, digits in (
            ("isr", 3), ("csr", 2), ("soc_vs_lb", 2), ("soc_vs_oracle", 2), ("makespan", 1),
            ("collisions", 2))]
        lines.append(f"| {row['phase']} | {row['family']} | {row['agents']} | {row['variant']} | "
                     + " | ".join(cells) + " |")
    frozen = {(r["family"], r["agents"], r["variant"]): r for r in rows if r["phase"] == "frozen"}
    for title, metric, table in (("CSR", "csr", CSR),
                                 ("SoC over the lower bound, solved instances", "soc_vs_lb",
                                  SOC_OVER_LOWER_BOUND)):
        methods = [m for m in METHODS if any(m in table.get(f, {}) for f in bench.families)]
        if not methods:
            continue
        lines += ["", f"## {title}, beside the published", "",
                  "| family | agents | " + " | ".join(bench.variants) + " | "
                  + " | ".join(methods) + " |",
                  "|---|---:|" + "---:|" * (len(bench.variants) + len(methods))]
        for family in bench.families:
            if family not in table:
                continue
            for agents in bench.agent_counts(family):
                ours = [_published(frozen[family, agents, v][metric])
                        if (family, agents, v) in frozen else "" for v in bench.variants]
                theirs = [_published(figure(table, family, m, agents)) for m in methods]
                lines.append(f"| {family} | {agents} | " + " | ".join(ours + theirs) + " |")
    lines += ["", "Published figures: the mean over all 128 instances of a family, POGEMA's "
              "on_target 'nothing' (our step-aside), 128 steps (256 on MovingAI). Sources: "
              + "; ".join(f"{m}: {SOURCES[m]}" for m in METHODS)
              + " (experiment/published.py).", "",
              "ISR: the share of agents on their goal at the episode's end; CSR: 1 if all are; "
              "SoC: the sum over agents of the step each last arrived (the episode's steps for one "
              "that did not); makespan: the largest (docs/swarm.md, \"The field's metrics\")."]
    return "\n".join(lines) + "\n"


def trained(bench: MapsBenchmark, how: str = "") -> str:
    """The table's words on the policies: trained (``how``: e.g. one-shot) on our maps, or none."""
    if not bench.learners:
        return f"The {REFERENCE} alone, nothing trained; "
    return (f"Trained {how + ' ' if how else ''}on {bench.train_maps} of our random maps x "
            f"{bench.train_episodes} episodes, {bench.train_agents} agents; ")


def _published(value: float | None) -> str:
    return "" if value is None or math.isnan(value) else f"{value:.2f}"
