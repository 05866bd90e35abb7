"""The layout of a run directory, and the atomic ways to write a small file into it.

    <out>/config.json          the resolved SwarmConfig
    <out>/episodes.csv         one row per finished episode (world.metrics)
    <out>/checkpoints/agent-<id>.ckpt  each agent's Q-tables (agent.agent_checkpoint; transport.slotfile)
    <out>/checkpoints/world.ckpt       the shared Q-table, where the agents share one (world.world_checkpoint)
    <out>/stats/world.json, <out>/stats/agent-<id>.json   closing statistics of each process
    <out>/stats/incarnation.json  how many times the run's world has started (next_incarnation)
    <out>/run.rrd              the Rerun recording
    <out>/rerun-parts/<role>.<pid>.rrd  each process's part of it, until merged into run.rrd
    <out>/run.lock             held by the run's launcher while it runs (transport.runlock)
"""

import errno
import json
import os
from pathlib import Path

CONFIG_FILE = "config.json"
EPISODES_FILE = "episodes.csv"
RECORDING_FILE = "run.rrd"
PARTS_DIR = "rerun-parts"
CHECKPOINT_DIR = "checkpoints"
STATS_DIR = "stats"
LOCK_FILE = "run.lock"


EXIT_NO_SPACE = 5
"""Exit code of a process that could not write the run's files for want of disk space (the
supervisor stops the run: what was written is resumable once there is space)."""


def out_of_space(error: BaseException) -> bool:
    """Whether ``error`` (or one it arose from) is a write refused for want of space."""
    while error is not None:
        if isinstance(error, OSError) and error.errno in (errno.ENOSPC, errno.EDQUOT):
            return True
        error = error.__cause__ or error.__context__  # type: ignore[assignment]
    return False


SPACE_PROBE_BYTES = 64 * 1024
"""What :func:`check_space` asks the disk for: about a recording's chunk of an episode."""


def check_space(folder: Path) -> None:
    """Raise the OSError (``ENOSPC``, ``EDQUOT``) of a disk that cannot give ``folder``
    :data:`SPACE_PROBE_BYTES` more; a probe file allocated there and removed. Any other error
    of the probe is left to whoever writes there next."""
    probe = Path(folder) / f".space-probe.{os.getpid()}"
    try:
        fd = os.open(probe, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.posix_fallocate(fd, 0, SPACE_PROBE_BYTES)
        finally:
            os.close(fd)
    except OSError as error:
        if out_of_space(error):
            raise
    finally:
        probe.unlink(missing_ok=True)


def stats_path(out_dir: Path, name: str) -> Path:
    """``<out>/stats/<name>.json``, e.g. name ``world`` or ``agent-3``."""
    return Path(out_dir) / STATS_DIR / f"{name}.json"


def next_incarnation(out_dir: Path) -> int:
    """Count one more start of the run's world in ``<out>/stats/incarnation.json`` and return
    it (1 for a run's first world): the incarnation its messages carry
    (``protocol.messages.Observation.world``)."""
    path = stats_path(out_dir, "incarnation")
    try:
        before = int(json.loads(path.read_text())["world"])
    except (OSError, ValueError, KeyError, TypeError):
        before = 0
    write_json_atomic(path, {"world": before + 1})
    return before + 1


def write_text_atomic(path: Path, text: str) -> None:
    """Write ``text`` to a temporary file, sync it and rename it over ``path``: readers, and a
    resume after a crash, see the old file or the new, never half of one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def write_json_atomic(path: Path, data: dict) -> None:
    """Write JSON atomically (:func:`write_text_atomic`)."""
    write_text_atomic(path, json.dumps(data, indent=2, sort_keys=True) + "\n")
