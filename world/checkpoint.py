"""The checkpoint of the shared Q-table the world keeps (``world.shared_table``), for ``--resume``.

Written at every episode's end, before that episode's row reaches ``episodes.csv``, with the
table as the agents checkpointed theirs then; a resumed world starts from it, so that its copy
and the agents' restored copies are equal again.
"""

from pathlib import Path

import numpy as np

from nnql_swarm.agent.checkpoint import CheckpointError, check_tables, read_versions
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol import slotfile
from nnql_swarm.protocol.runfiles import CHECKPOINT_DIR
from nnql_swarm.world.shared_table import SharedTable

FILE = "world.ckpt"


def table_path(out_dir: Path) -> Path:
    return Path(out_dir) / CHECKPOINT_DIR / FILE


def save(path: Path, table: tuple[np.ndarray, np.ndarray], episode: int,
         config: SwarmConfig) -> None:
    """Write the shared table after ``episode``; readers see the old file or the new."""
    q_ds, q_ca = table
    slotfile.write(path, {"q_ds": q_ds, "q_ca": q_ca, "episode": episode,
                          "n_agents": config.n_agents, "algo": config.algo})


def load(path: Path, config: SwarmConfig, episode: int) -> tuple[np.ndarray, np.ndarray]:
    """The shared table a run resumed after ``episode`` starts from; raises CheckpointError
    naming the file if it is missing, damaged, of another run shape or of another episode."""
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"{path}: missing (the shared table of episode {episode})")
    versions = read_versions(path, ("q_ds", "q_ca", "episode", "n_agents", "algo"))
    # a world killed after writing this file and before the episode's row holds the table of an
    # episode past episodes.csv; the version before it is the one the row before recorded
    fields = next((v for v in versions if int(v["episode"]) == episode), versions[0])
    check_tables(path, fields, SharedTable(config).tables())
    owner = (int(fields["n_agents"]), str(fields["algo"]))
    if owner != (config.n_agents, config.algo):
        raise CheckpointError(f"{path}: belongs to a run of {owner[0]} agents ({owner[1]}), not "
                              f"{config.n_agents} ({config.algo})")
    if int(fields["episode"]) != episode:
        raise CheckpointError(f"{path}: holds the table after episode {int(fields['episode'])}, "
                              f"episodes.csv ends with episode {episode}")
    return fields["q_ds"], fields["q_ca"]
