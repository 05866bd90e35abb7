"""Per-episode scalars and text logs buffered and sent to Rerun as columns, a few calls at a time.

The Rerun SDK keeps native memory for every logging call it has seen (``bench/rerun_calls.py``
measures it: never given back, however small the value), so a process that logs a
dozen scalars per episode at tens of episodes a second grows without bound. Sent as columns, a
batch of values costs one call per entity path. :class:`FlushClock` says when a batch is due:
after ``most`` items or ``seconds`` of wall time, whichever comes first, so a live viewer lags by
at most that; the values and their times are the same however they are batched.
"""

import time

import rerun as rr

FLUSH_SECONDS = 2.0
"""The most a live viewer lags behind the run's per-episode logging."""


class FlushClock:
    """Due after ``most`` items since the last flush, or ``seconds`` of wall time."""

    def __init__(self, most: int, seconds: float = FLUSH_SECONDS) -> None:
        self.most, self.seconds = most, seconds
        self._last = time.monotonic()

    def due(self, items: int) -> bool:
        return items >= self.most or (items > 0 and time.monotonic() - self._last >= self.seconds)

    def flushed(self) -> None:
        self._last = time.monotonic()


class SeriesColumns:
    """Scalars per entity path with their ``tick`` and ``episode``, sent one call per path."""

    def __init__(self) -> None:
        self._series: dict[str, tuple[list[int], list[int], list[float]]] = {}

    def add(self, path: str, tick: int, episode: int, value: float) -> None:
        ticks, episodes, values = self._series.setdefault(path, ([], [], []))
        ticks.append(tick)
        episodes.append(episode)
        values.append(float(value))

    def send(self, stream: rr.RecordingStream) -> None:
        for path, (ticks, episodes, values) in self._series.items():
            stream.send_columns(path, time_columns(ticks, episodes),
                                rr.Scalars.columns(scalars=values))
        self._series = {}


class TextColumns:
    """Text log lines of one entity path with their ``tick``, ``episode`` and level."""

    def __init__(self, path: str) -> None:
        self.path = path
        self._lines: list[tuple[int, int, str, str]] = []

    def add(self, tick: int, episode: int, text: str, level: str) -> None:
        self._lines.append((tick, episode, text, level))

    def send(self, stream: rr.RecordingStream) -> None:
        if not self._lines:
            return
        ticks, episodes, texts, levels = zip(*sorted(self._lines, key=lambda line: line[0]))
        stream.send_columns(self.path, time_columns(ticks, episodes),
                            rr.TextLog.columns(text=texts, level=levels))
        self._lines = []


def time_columns(ticks, episodes) -> list:
    """The two timelines of every recording, as the index of a ``send_columns`` call."""
    return [rr.TimeColumn("tick", sequence=ticks), rr.TimeColumn("episode", sequence=episodes)]
