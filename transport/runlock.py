"""One owner per run folder: an exclusive lock on ``<out>/run.lock``, held for the run's life.

A run, or a ``--resume``, takes the lock before it writes anything into its folder, and a second
one into the same folder is refused (:class:`RunLocked`) instead of interleaving its rows with
the first's. The lock is ``flock(2)``'s: the kernel drops it when its holder ends, however it
ends (``kill -9``, a crash), so a stopped run never leaves its folder locked. The file holds the
holder's pid, only to name it in the refusal.
"""

import fcntl
import os
from pathlib import Path

from nnql_swarm.transport.runfiles import LOCK_FILE


class RunLocked(Exception):
    """Another process holds the run folder; the message says which and what to do."""


class RunLock:
    """The lock of the run folder ``out`` (which must exist), taken at once or refused:
    raises RunLocked if another process holds it, OSError if the file cannot be opened or
    written (the lock then let go)."""

    def __init__(self, out: Path) -> None:
        self.path = Path(out) / LOCK_FILE
        self._fd: int | None = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o644)
        try:
            fcntl.flock(self._fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(self._fd, 32, 0).decode(errors="replace").strip()
            self.release()
            raise RunLocked(f"{out} is in use by another run (process {holder or '?'}): one run "
                            f"at a time in a folder; wait for it to end, or choose another --out")
        try:
            os.ftruncate(self._fd, 0)
            os.pwrite(self._fd, f"{os.getpid()}\n".encode(), 0)
        except OSError:  # a full disk: the caller says so, and the folder is nobody's
            self.release()
            raise

    def release(self) -> None:
        """Give the folder up (closing the file drops the lock); again: nothing."""
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> "RunLock":
        return self

    def __exit__(self, *_exception) -> None:
        self.release()
