"""What every command-line entry point shares: one-line usage errors with exit code 2, ``--version``,
and the progress bar of long work."""

import argparse
import sys
import threading
from importlib import metadata

from tqdm import tqdm

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def package_version() -> str:
    """The installed version of the project (``pyproject.toml``'s)."""
    try:
        return metadata.version("nnql-swarm")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (no usage dump) and exit code 2, with
    ``--version``. Its name is the command's as it was called (``swarm.py``, ``nnql-swarm``)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action="version",
                          version=f"%(prog)s (nnql-swarm {package_version()})")

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


PLAIN_INTERVAL_S = 5.0
"""Where stderr is not a terminal (CI logs, files), the bar is written at most this often."""


def progress(total: int, unit: str, desc: str = "") -> tqdm:
    """A progress bar on stderr: redrawn in place on a terminal; elsewhere a line of its own at
    most every few seconds, so that logs stay short and readable line by line. One process draws
    it, so its lock is a thread lock (tqdm's default adds a multiprocessing semaphore, which a
    process stopped by a signal leaves behind for the resource tracker to warn about)."""
    tqdm.set_lock(threading.RLock())
    if sys.stderr.isatty():
        return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True)
    return tqdm(total=total, unit=unit, desc=desc, file=_Lines(), mininterval=PLAIN_INTERVAL_S,
                ascii=True, ncols=100)


class _Lines:
    """stderr as a bar's stream where it is not a terminal: each redraw becomes a line."""

    def __init__(self) -> None:
        self.last = ""

    def write(self, text: str) -> None:
        line = text[1:].rstrip()
        done = line.split("[")[0]  # the count; closing redraws the last one with a later time
        if text.startswith("\r") and done != self.last:
            sys.stderr.write(line + "\n")
            self.last = done

    def flush(self) -> None:
        sys.stderr.flush()
