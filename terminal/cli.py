"""What every command-line entry point shares: one-line usage errors with exit code 2, ``--version``,
and the progress bar of long work."""

import argparse
import sys
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
    most every few seconds, so that logs stay short and readable line by line."""
    if sys.stderr.isatty():
        return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True)
    return tqdm(total=total, unit=unit, desc=desc, file=_Lines(), mininterval=PLAIN_INTERVAL_S,
                ascii=True, ncols=100)


class _Lines:
    """stderr as a bar's stream where it is not a terminal: each redraw becomes a line."""

    def write(self, text: str) -> None:
        if text.startswith("\r"):
            sys.stderr.write(text[1:].rstrip() + "\n")

    def flush(self) -> None:
        sys.stderr.flush()
