"""The run's ``episodes.csv``: one row per finished episode, flushed to disk as it ends.

The deterministic columns come from the world (``world.engine.EPISODE_FIELDS``); wall-clock
columns (``WALL_CLOCK_FIELDS``) follow them and are the only ones allowed to differ between two
runs of the same config.
"""

import csv
import os
from pathlib import Path

from nnql_swarm.world.engine import EPISODE_FIELDS

WALL_CLOCK_FIELDS = ("duration_s", "ticks_per_s", "max_tick_ms", "rejected")
"""Wall-clock columns: the episode's duration, its tick rate, its slowest tick, and how many
malformed or out-of-place messages the world had rejected by its end."""
COLUMNS = EPISODE_FIELDS + WALL_CLOCK_FIELDS


class EpisodeWriter:
    """Appends episode rows to a CSV file, each one flushed (and synced to disk, unless ``sync``
    is off) before the next tick.

    Opening an existing file (``--resume``) first cuts off a last line that a crash left half
    written, so the file holds whole rows only.
    """

    def __init__(self, path: Path, sync: bool = True) -> None:
        self.path = Path(path)
        self.sync = sync
        drop_partial_line(self.path)
        fresh = not self.path.exists() or self.path.stat().st_size == 0
        self._file = open(self.path, "a", newline="")
        self._csv = csv.DictWriter(self._file, fieldnames=COLUMNS)
        if fresh:
            self._csv.writeheader()
            self._sync()

    def write(self, row: dict, duration_s: float, ticks: int, max_tick_s: float = 0.0,
              rejected: int = 0) -> None:
        rate = ticks / duration_s if duration_s > 0 else 0.0
        self._csv.writerow({
            **row, "duration_s": f"{duration_s:.4f}", "ticks_per_s": f"{rate:.1f}",
            "max_tick_ms": f"{max_tick_s * 1000:.1f}", "rejected": rejected,
        })
        self._sync()

    def _sync(self) -> None:
        self._file.flush()
        if self.sync:
            os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> "EpisodeWriter":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def drop_partial_line(path: Path) -> None:
    """Cut a trailing line that has no newline (a write interrupted by a crash)."""
    if not path.exists():
        return
    data = path.read_bytes()
    if data and not data.endswith(b"\n"):
        with open(path, "r+b") as f:
            f.truncate(data.rfind(b"\n") + 1)


def keep_rows(path: Path, count: int) -> None:
    """Cut ``episodes.csv`` after its header and first ``count`` rows (synced to disk)."""
    with open(path, "r+b") as f:
        lines = f.read().splitlines(keepends=True)
        f.truncate(sum(len(line) for line in lines[:1 + count]))
        os.fsync(f.fileno())


def read_episodes(path: Path) -> list[dict]:
    """The rows of an ``episodes.csv`` as dicts of strings."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))
