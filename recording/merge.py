"""The run's recording in one file: each process's part merged into ``<out>/run.rrd``, with
Rerun's own ``rerun rrd optimize`` (the Python SDK has no merge), which merges and compacts: the
world sends each agent's entities as chunks of their own every episode, and compacted they take
about a sixth of the room (the default run: 12.4 MiB of 8,218 chunks, 1.9 MiB of 211).

The launcher merges when the run ends, Ctrl-C included; an existing ``run.rrd`` of a resumed run
is merged in too; the parts are kept if merging fails.
"""

import os
import subprocess
import sys
from pathlib import Path

from nnql_swarm.recording.binary import rerun_binary
from nnql_swarm.transport.runfiles import PARTS_DIR, RECORDING_FILE


def merge_parts(out: Path) -> Path | None:
    """Merge ``<out>/rerun-parts/*.rrd`` (and an existing ``run.rrd``) into ``<out>/run.rrd``.

    Returns the recording's path, or None if there was nothing to merge or merging failed (then
    the parts stay where they are, and a line on stderr says so).
    """
    out = Path(out)
    parts_dir = out / PARTS_DIR
    parts = sorted(parts_dir.glob("*.rrd")) if parts_dir.is_dir() else []
    if not parts:
        return None
    target = out / RECORDING_FILE
    inputs = ([target] if target.exists() else []) + parts
    tmp = target.with_name(target.name + ".tmp")
    for extra in ([], ["--continue-on-error"]):
        try:
            result = subprocess.run(
                [*rerun_binary(), "rrd", "optimize", *extra, *map(str, inputs), "-o", str(tmp)],
                capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.TimeoutExpired) as error:
            print(f"rerun: merging the recording failed ({error}); the parts are in {parts_dir}",
                  file=sys.stderr)
            return None
        if result.returncode == 0:
            break
    else:
        tmp.unlink(missing_ok=True)
        reason = result.stderr.strip().splitlines()[-1:] or ["unknown error"]
        print(f"rerun: merging the recording failed ({reason[0]}); the parts are in {parts_dir}",
              file=sys.stderr)
        return None
    os.replace(tmp, target)
    if extra:
        print(f"rerun: some parts were damaged; merged what was readable into {target}, "
              f"kept the parts in {parts_dir}", file=sys.stderr)
        return target
    for part in parts:
        part.unlink()
    try:
        parts_dir.rmdir()
    except OSError:
        pass
    return target
