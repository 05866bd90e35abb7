"""A learner's tables as saved: reading a checkpoint file's fields and versions
(``transport.slotfile``) and checking its tables, refusing with one error naming the file
(:class:`CheckpointError`). An agent's checkpoints (``agent.agent_checkpoint``) and the world's shared
table (``world.world_checkpoint``) are read with them."""

from pathlib import Path

import numpy as np

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport import slotfile


class CheckpointError(ValueError):
    """A checkpoint that cannot be used: unreadable, corrupt or from another run shape."""



def read_fields(path: Path, expected: tuple[str, ...]) -> dict:
    """Every field of a checkpoint, by name (the tables as arrays); raises CheckpointError naming
    the file if it cannot be read or lacks one of ``expected``."""
    return _read(path, expected, all_versions=False)[0]



def read_versions(path: Path, expected: tuple[str, ...]) -> list[dict]:
    """The checkpoint file's whole versions, the newest first (``transport.slotfile.read_all``:
    the last and the one before), as :func:`read_fields` gives each."""
    return _read(path, expected, all_versions=True)



def _read(path: Path, expected: tuple[str, ...], all_versions: bool) -> list[dict]:
    path = Path(path)
    try:
        versions = slotfile.read_all(path) if all_versions else [slotfile.read(path)]
    except (OSError, slotfile.SlotFileError) as error:
        raise CheckpointError(f"{path}: not a readable checkpoint ({error})") from None
    for fields in versions:
        missing = [key for key in expected if key not in fields]
        if missing:
            raise CheckpointError(f"{path}: corrupt checkpoint, missing {', '.join(missing)}")
    return versions



def check_run(path: Path, fields: dict, config: SwarmConfig) -> None:
    """That a checkpoint is the run's own (``run``: its identity, ``SwarmConfig.identity``);
    raises CheckpointError naming the file. One written before checkpoints carried it passes."""
    run = fields.get("run")
    if run is not None and str(run) != config.identity:
        raise CheckpointError(f"{path}: belongs to another run (identity {run}), not this one "
                              f"({config.identity})")


def check_tables(path: Path, fields: dict, tables: tuple[np.ndarray, np.ndarray]) -> None:
    """That a checkpoint's ``q_ds`` and ``q_ca`` have the shapes of ``tables`` and hold only
    finite values; raises CheckpointError naming the file."""
    for name, current in zip(("q_ds", "q_ca"), tables):
        shape = current.shape
        if not isinstance(fields[name], np.ndarray):
            raise CheckpointError(f"{path}: {name} is not a table")
        if fields[name].shape != shape:
            raise CheckpointError(f"{path}: {name} of shape {fields[name].shape}, expected {shape}")
    if not (np.isfinite(fields["q_ds"]).all() and np.isfinite(fields["q_ca"]).all()):
        raise CheckpointError(f"{path}: Q-tables hold non-finite values")

