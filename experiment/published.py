"""The field's published results on POGEMA's instances (``maps/pogema/``, 128 instances a
family), which the POGEMA suite's tables (``experiment.pogema``, ``experiment.pogema_lifelong``)
put beside ours: on the one-shot instances (POGEMA's ``on_target: nothing``) each method's CSR
(the share of instances where every agent is on its goal at the end) per family and agent count,
and on the random maps its sum of costs over the lower bound on the instances it solved; on the
lifelong instances (``on_target: restart``) each method's throughput, goals reached a step.

Sources: POGEMA's benchmark (Skrynnik et al., "POGEMA: A Benchmark Platform for Cooperative
Multi-Agent Pathfinding", ICLR 2025, and its published evaluation data) for LaCAM, SCRIMP and DCC;
the MAPF-GPT-DDG paper (Andreychuk et al., "Advancing Learnable Multi-Agent Pathfinding Solvers
with Active Fine-Tuning", 2025) for MAPF-GPT-DDG and MAPF-GPT-85M and its own runs of the others.
Each figure is the mean over the same 128 instances, as issue 43 gathered them. POGEMA's own
evaluation data (``raw_data_MAPF/<family>/<method>.json`` of CognitiveAISystems/pogema-benchmark at
commit 3303133) agrees for LaCAM, and for DCC on the warehouse and MovingAI, but gives SCRIMP
lower figures and DCC on random maps and mazes slightly different ones (docs/swarm.md, "POGEMA's
own instances").
"""

SOURCES = {
    "LaCAM": "POGEMA (ICLR 2025) evaluation data",
    "MAPF-GPT-DDG": "MAPF-GPT-DDG paper (Andreychuk et al., 2025)",
    "MAPF-GPT-85M": "MAPF-GPT-DDG paper (Andreychuk et al., 2025)",
    "SCRIMP": "POGEMA (ICLR 2025) / MAPF-GPT-DDG paper",
    "DCC": "POGEMA (ICLR 2025) / MAPF-GPT-DDG paper",
}
"""Each method's figures, where they come from."""

METHODS = tuple(SOURCES)


def _by_count(counts: tuple[int, ...], **rows: tuple[float, ...]) -> dict[str, dict[int, float]]:
    return {method.replace("_", "-"): dict(zip(counts, values)) for method, values in rows.items()}


CSR: dict[str, dict[str, dict[int, float]]] = {
    "random": _by_count((8, 32, 64), LaCAM=(1, 1, 1), MAPF_GPT_DDG=(1, 1, 0.95),
                        MAPF_GPT_85M=(1, 1, 0.94), SCRIMP=(1, 0.96, 0.70), DCC=(1, 0.73, 0.06)),
    "mazes": _by_count((8, 32, 64), LaCAM=(1, 1, 0.91), MAPF_GPT_DDG=(1, 1, 0.82),
                       MAPF_GPT_85M=(1, 0.97, 0.70), SCRIMP=(1, 0.55, 0.15),
                       DCC=(0.96, 0.36, 0.02)),
    "warehouse": _by_count((64, 128, 192), LaCAM=(1, 1, 1), MAPF_GPT_DDG=(1, 1, 0.55),
                           MAPF_GPT_85M=(1, 0.98, 0.37), SCRIMP=(1, 0.98, 0.91),
                           DCC=(0.86, 0.12, 0)),
    "movingai": _by_count((64, 128, 256), LaCAM=(1, 0.99, 0.98), MAPF_GPT_DDG=(1, 0.95, 0.75),
                          MAPF_GPT_85M=(1, 0.94, 0.74), SCRIMP=(0.98, 0.94, 0.77),
                          DCC=(0.97, 0.88, 0.34)),
}
"""CSR per family, method and agent count."""

SOC_OVER_LOWER_BOUND: dict[str, dict[str, dict[int, float]]] = {
    "random": _by_count((8, 32, 64), LaCAM=(1.01, 1.10, 1.33), MAPF_GPT_DDG=(1.07, 1.32, 1.97),
                        SCRIMP=(1.09, 1.44, 2.12), DCC=(1.14, 1.82, 2.64)),
}
"""The sum of costs over its lower bound (the sum of the shortest paths) on the instances a
method solved, per family, method and agent count."""


THROUGHPUT_SOURCES = {
    "RHCR": "POGEMA (ICLR 2025) evaluation data",
    "Follower": "POGEMA (ICLR 2025) evaluation data",
    "MATS-LP": "POGEMA (ICLR 2025) evaluation data",
}
"""Each method's lifelong figures, where they come from: POGEMA's benchmark (Skrynnik et al.,
ICLR 2025) and its published evaluation data, the mean over a family's 128 lifelong instances
(``<family>-lmapf.yaml``), as issue 44 gathered them."""

THROUGHPUT_METHODS = tuple(THROUGHPUT_SOURCES)

THROUGHPUT: dict[str, dict[str, dict[int, float]]] = {
    "random": _by_count((8, 32, 64), RHCR=(0.63, 2.29, 3.82), Follower=(0.60, 1.83, 2.47),
                        MATS_LP=(0.61, 1.91, 2.43)),
    "mazes": _by_count((8, 32, 64), RHCR=(0.48, 1.70, 2.59), Follower=(0.45, 1.31, 1.61),
                       MATS_LP=(0.46, 1.32, 1.51)),
    "warehouse": _by_count((32, 128, 192), RHCR=(1.22, 3.49, 1.57), Follower=(1.13, 3.15, 3.94),
                           MATS_LP=(1.11, 1.82, 1.91)),
    "movingai": _by_count((64, 128, 256), RHCR=(1.57, 3.00, 5.13), Follower=(1.50, 2.82, 4.81),
                          MATS_LP=(1.57, 2.98, 4.69)),
}
"""Throughput (goals reached a step) per family, method and agent count on the lifelong
instances. RHCR's 1.57 on the warehouse at 192 agents: it runs out of planning time there."""


def figure(table: dict[str, dict[str, dict[int, float]]], family: str, method: str,
           agents: int) -> float | None:
    """A published figure, or None where the sources give none."""
    return table.get(family, {}).get(method, {}).get(agents)
