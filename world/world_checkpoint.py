"""The checkpoint of the shared Q-table the world keeps (``world.shared_table``), for ``--resume``.

Written at every episode's end, before that episode's row reaches ``episodes.csv``: the table as
the agents checkpointed theirs at that end tick, and the learning records the end tick brought,
which the run applies at the next episode's first tick (``world.shared_table.SharedState``). A
resumed world starts from both, so that its copy, the agents' restored copies and the updates
their first observations carry are those of the run left alone.
"""

from pathlib import Path

from nnql_swarm.learning.saved import CheckpointError, check_run, check_tables, read_versions
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport import slotfile
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR
from nnql_swarm.world.shared_table import SharedState, SharedTable

FILE = "world.ckpt"
FIELDS = ("q_ds", "q_ca", "records", "episode", "n_agents", "algo")


def table_path(out_dir: Path) -> Path:
    return Path(out_dir) / CHECKPOINT_DIR / FILE


def save(path: "Path | slotfile.SlotFile", state: SharedState, episode: int,
         config: SwarmConfig) -> None:
    """Write the shared table after ``episode``; readers see the old file or the new."""
    records = [[agent, list(integers), list(rewards)] for agent, integers, rewards in state.records]
    slotfile.write(path, {"q_ds": state.q_ds, "q_ca": state.q_ca, "records": records,
                          "episode": episode, "n_agents": config.n_agents, "algo": config.algo,
                          "run": config.identity})


def episodes(path: Path) -> list[int]:
    """The episodes whose tables the file holds, the newest first; raises CheckpointError."""
    return [int(v["episode"]) for v in read_versions(path, FIELDS)]


def load(path: Path, config: SwarmConfig, episode: int) -> SharedState:
    """The shared state a run resumed after ``episode`` starts from; raises CheckpointError
    naming the file if it is missing, damaged, of another run shape or holds no version of that
    episode (the file keeps the newest two)."""
    path = Path(path)
    if not path.exists():
        raise CheckpointError(f"{path}: missing (the shared table of episode {episode})")
    versions = read_versions(path, FIELDS)
    fields = next((v for v in versions if int(v["episode"]) == episode), versions[0])
    check_tables(path, fields, SharedTable(config).tables())
    owner = (int(fields["n_agents"]), str(fields["algo"]))
    if owner != (config.n_agents, config.algo):
        raise CheckpointError(f"{path}: belongs to a run of {owner[0]} agents ({owner[1]}), not "
                              f"{config.n_agents} ({config.algo})")
    check_run(path, fields, config)
    if int(fields["episode"]) != episode:
        raise CheckpointError(f"{path}: holds the table after episode {int(fields['episode'])}, "
                              f"not after episode {episode}")
    try:
        records = tuple((int(agent), tuple(int(i) for i in integers),
                         tuple(float(r) for r in rewards))
                        for agent, integers, rewards in fields["records"])
    except (TypeError, ValueError) as error:
        raise CheckpointError(f"{path}: damaged learning records ({error})") from None
    table = SharedTable(config)
    if not all(table.accepts((integers, rewards)) for _, integers, rewards in records):
        raise CheckpointError(f"{path}: a learning record that does not fit the table")
    return SharedState(fields["q_ds"], fields["q_ca"], records)
