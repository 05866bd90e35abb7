"""The run's recording in one file: each process's part merged into ``<out>/run.rrd``, with
Rerun's own ``rerun rrd optimize`` (the Python SDK has no merge), which merges and compacts: the
world sends each agent's entities as chunks of their own every episode, and compacted they take
about a sixth of the room (the default run: 12.4 MiB of 8,218 chunks, 1.9 MiB of 211).

The launcher merges when the run ends, Ctrl-C included; an existing ``run.rrd`` of a resumed run
is merged in too; the parts are kept if merging fails.

A resumed run plays again everything past its resume point, and the stopped run may have recorded
some of that already: its processes send each tick to the recording as it closes, ahead of the
rows and checkpoints that make an episode durable (after ``kill -9`` the world's part can hold
ticks dozens of episodes past the last row, when the thread that writes the rows fell behind).
So before a resumed run starts, :func:`cut_at` keeps of the stopped run's recording (its parts
and ``run.rrd``) only the rows before the resume point's tick, and every episode is recorded
once. (``rerun rrd split`` cuts too, but renames the recording, and ``rerun rrd route``, which
would give it its name back, panics on some of its pieces: Rerun 0.41.)
"""

import os
import shutil
import subprocess
import sys
from pathlib import Path

from nnql_swarm.recording.binary import rerun_binary
from nnql_swarm.transport.runfiles import PARTS_DIR, RECORDING_FILE

CUT_DIR = "rerun-cut"  # scratch room of cut_at, under <out>


def _rerun(*args: str) -> str | None:
    """Run ``rerun rrd <args>``; None if it worked, else why not (one line)."""
    try:
        result = subprocess.run([*rerun_binary(), "rrd", *args], capture_output=True, text=True,
                                timeout=600)
    except (OSError, subprocess.TimeoutExpired) as error:
        return str(error)
    if result.returncode == 0:
        return None
    return (result.stderr.strip().splitlines()[-1:] or ["unknown error"])[0]


def _parts(out: Path) -> list[Path]:
    parts_dir = out / PARTS_DIR
    return sorted(parts_dir.glob("*.rrd")) if parts_dir.is_dir() else []


def _drop_parts(out: Path, parts: list[Path]) -> None:
    for part in parts:
        part.unlink()
    try:
        (out / PARTS_DIR).rmdir()
    except OSError:
        pass


def merge_parts(out: Path) -> Path | None:
    """Merge ``<out>/rerun-parts/*.rrd`` (and an existing ``run.rrd``) into ``<out>/run.rrd``.

    Returns the recording's path, or None if there was nothing to merge or merging failed (then
    the parts stay where they are, and a line on stderr says so).
    """
    out = Path(out)
    parts_dir = out / PARTS_DIR
    parts = _parts(out)
    if not parts:
        return None
    target = out / RECORDING_FILE
    inputs = ([target] if target.exists() else []) + parts
    tmp = target.with_name(target.name + ".tmp")
    for extra in ([], ["--continue-on-error"]):
        failed = _rerun("optimize", *extra, *map(str, inputs), "-o", str(tmp))
        if failed is None:
            break
    else:
        tmp.unlink(missing_ok=True)
        print(f"rerun: merging the recording failed ({failed}); the parts are in {parts_dir}",
              file=sys.stderr)
        return None
    os.replace(tmp, target)
    if extra:
        print(f"rerun: some parts were damaged; merged what was readable into {target}, "
              f"kept the parts in {parts_dir}", file=sys.stderr)
        return target
    _drop_parts(out, parts)
    return target


def cut_at(out: Path, tick: int, run_id: str) -> None:
    """Keep of the recording in ``out`` (its parts and ``run.rrd``, merged into ``run.rrd``) only
    the ticks before ``tick``, the first tick a resumed run plays (0: none is kept). The resumed
    run sends its blueprint and static data again; kept are the stopped run's static data and
    its rows before ``tick``. If that fails, a line on stderr says so and every file stays as it
    was (nothing is lost; the episodes played again may then be in the recording twice)."""
    out = Path(out)
    target, parts = out / RECORDING_FILE, _parts(out)
    inputs = ([target] if target.exists() else []) + parts
    if not inputs:
        return
    if tick <= 0:  # the run starts afresh: it records everything again
        target.unlink(missing_ok=True)
        _drop_parts(out, parts)
        return
    scratch = out / CUT_DIR
    shutil.rmtree(scratch, ignore_errors=True)
    scratch.mkdir()
    try:
        whole, kept = scratch / "whole.rrd", scratch / "kept.rrd"
        # parts torn by kill -9 end in a half-written message: read what is whole
        failed = _rerun("optimize", "--continue-on-error", *map(str, inputs), "-o", str(whole))
        if failed is None:
            try:
                _keep_before(whole, tick, run_id, kept)
            except Exception as error:  # the SDK's reader and writer raise their own kinds
                failed = str(error).strip().splitlines()[0] if str(error).strip() else repr(error)
        if failed is not None:
            print(f"rerun: cutting the recording at the resume point (tick {tick}) failed "
                  f"({failed}); the episodes played again may be in {target} twice",
                  file=sys.stderr)
            return
        os.replace(kept, target)
        _drop_parts(out, parts)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def _keep_before(source: Path, tick: int, run_id: str, target: Path) -> None:
    """Write the recording ``run_id`` of ``source`` into ``target``, its rows at or past
    ``tick`` left out (static chunks, and chunks with no tick, kept whole)."""
    import pyarrow.compute as pc
    import rerun as rr

    from nnql_swarm.recording.sinks import APP_ID

    def before(chunk: rr.chunk.Chunk) -> list[rr.chunk.Chunk]:
        if chunk.is_static or "tick" not in chunk.timeline_names:
            return [chunk]
        batch = chunk.to_record_batch()
        keep = pc.less(batch.column("tick"), tick)
        kept = pc.sum(keep).as_py() or 0
        if kept == batch.num_rows:
            return [chunk]
        return rr.chunk.Chunk.from_record_batch(batch.filter(keep)) if kept else []

    reader = rr.chunk.RrdReader(source)
    [store] = [s for s in reader.recordings() if s.recording_id == run_id]
    reader.stream(store=store).flat_map(before).write_rrd(target, application_id=APP_ID,
                                                          recording_id=run_id)
