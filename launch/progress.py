"""A tiny dependency-free progress bar for long runs, written to stderr.

On a terminal the bar is redrawn in place (``\\r``) at most ``TTY_INTERVAL`` seconds apart; elsewhere
(CI logs, files) a plain line is printed at most every ``PLAIN_INTERVAL`` seconds, so logs stay short.
The last state is always shown on :meth:`Progress.close`::

    with Progress(total=1000, label="episodes") as bar:
        for _ in range(1000):
            bar.update(collisions=3)
"""

import sys
import time
from typing import TextIO

TTY_INTERVAL = 0.1
PLAIN_INTERVAL = 5.0
BAR_WIDTH = 24


def format_duration(seconds: float) -> str:
    """``75`` -> ``"1:15"``, ``3725`` -> ``"1:02:05"``."""
    seconds = max(0, int(round(seconds)))
    hours, rest = divmod(seconds, 3600)
    minutes, secs = divmod(rest, 60)
    return f"{hours}:{minutes:02d}:{secs:02d}" if hours else f"{minutes}:{secs:02d}"


class Progress:
    """Counts work done out of ``total`` and shows it with elapsed time, ETA and extra fields."""

    def __init__(self, total: int, label: str, stream: TextIO = sys.stderr) -> None:
        self.total = max(0, int(total))
        self.label = label
        self.stream = stream
        self.done = 0
        self.fields: dict[str, object] = {}
        self._tty = bool(getattr(stream, "isatty", lambda: False)())
        self._interval = TTY_INTERVAL if self._tty else PLAIN_INTERVAL
        self._start = time.monotonic()
        self._last_draw = -float("inf")
        self._drawn_width = 0
        self._closed = False

    def update(self, n: int = 1, **fields: object) -> None:
        """Add ``n`` units of work done; ``fields`` (e.g. ``collisions=3``) are shown after the bar."""
        self.done = min(self.total, self.done + n) if self.total else self.done + n
        self.fields.update(fields)
        now = time.monotonic()
        if now - self._last_draw >= self._interval:
            self._draw(now)

    def close(self) -> None:
        """Show the final state and end the line."""
        if self._closed:
            return
        self._closed = True
        self._draw(time.monotonic())
        if self._tty:
            self.stream.write("\n")
            self.stream.flush()

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    def line(self, now: float | None = None) -> str:
        """The text of the bar as it would be drawn now."""
        now = time.monotonic() if now is None else now
        elapsed = now - self._start
        fraction = self.done / self.total if self.total else 1.0
        filled = int(round(BAR_WIDTH * fraction))
        bar = "#" * filled + "-" * (BAR_WIDTH - filled)
        if 0 < self.done < self.total:
            eta = format_duration(elapsed * (self.total - self.done) / self.done)
        else:
            eta = "0:00" if self.done >= self.total else "?"
        text = (
            f"{self.label} [{bar}] {self.done}/{self.total} {fraction:4.0%} "
            f"elapsed {format_duration(elapsed)} eta {eta}"
        )
        if self.fields:
            text += "  " + " ".join(f"{key}={value}" for key, value in self.fields.items())
        return text

    def _draw(self, now: float) -> None:
        self._last_draw = now
        text = self.line(now)
        if self._tty:
            padding = " " * max(0, self._drawn_width - len(text))
            self.stream.write("\r" + text + padding)
            self._drawn_width = len(text)
        else:
            self.stream.write(text + "\n")
        self.stream.flush()
