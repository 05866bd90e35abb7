"""What every command-line entry point shares: one-line usage errors with exit code 2, and the
progress bar of long work."""

import argparse
import sys

from tqdm import tqdm

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (no usage dump) and exit code 2."""

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
