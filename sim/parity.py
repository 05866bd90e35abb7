"""What a simulated run must equal when nothing in it can make anyone miss: ``--in-process``.

The in-process runner (``sim.inprocess``) runs the same world and brains in rank order, every
intent known when it is asked for. A simulated run whose faults are all benign (latency,
duplicates, reordering: far shorter than any time-out) must give the very same episodes and the
very same Q-tables, bit for bit.
"""

import tempfile
from pathlib import Path

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.sim.inprocess import run_in_process
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes


def in_process_reference(config: SwarmConfig, scratch: Path | None = None) -> tuple[list, list]:
    """``(rows, fingerprints)`` of the in-process run of ``config``: its ``episodes.csv``'s
    deterministic columns (as the file holds them) and each agent's final tables."""
    prints: dict[int, str] = {}
    last = config.episodes - 1

    def at_episode_end(brain, episode: int) -> None:
        if episode == last:
            prints[brain.agent] = agent_checkpoint.fingerprint(brain)

    with tempfile.TemporaryDirectory(prefix="nnql-ref-", dir=scratch) as tmp:
        run_in_process(config, Path(tmp), checkpoints=False, on_episode_end=at_episode_end)
        rows = [tuple(row[f] for f in EPISODE_FIELDS)
                for row in read_episodes(Path(tmp) / "episodes.csv")]
    return rows, [prints.get(i) for i in range(config.n_agents)]


def as_written(rows: list[dict]) -> list[tuple]:
    """Simulated rows as ``episodes.csv`` holds them (every value as its ``str``)."""
    return [tuple(str(row[f]) for f in EPISODE_FIELDS) for row in rows]


def parity_failures(config: SwarmConfig, rows: list[dict], fingerprints: list,
                    scratch: Path | None = None) -> list[str]:
    """How a benign simulated run (its rows and final tables) differs from ``--in-process``."""
    reference_rows, reference_prints = in_process_reference(config, scratch)
    failures = []
    mine = as_written(rows)
    if mine != reference_rows:
        first = next((i for i, (a, b) in enumerate(zip(mine, reference_rows)) if a != b),
                     min(len(mine), len(reference_rows)))
        failures.append(f"episode {first} differs from --in-process: "
                        f"{mine[first] if first < len(mine) else None} against "
                        f"{reference_rows[first] if first < len(reference_rows) else None}")
    differ = [i for i, (a, b) in enumerate(zip(fingerprints, reference_prints)) if a != b]
    if differ:
        failures.append(f"agents {differ} learned other tables than in --in-process")
    return failures
