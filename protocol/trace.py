"""Timestamps of the steps of each tick, per process: off unless ``NNQL_TRACE`` names a directory.

``bench/tick_trace.py`` turns them into where a tick's time goes. Each process marks the steps it
takes with the tick they belong to (``trace.mark(DECIDE, tick)``), on the one clock all processes
of a machine share (``time.perf_counter``: CLOCK_MONOTONIC on Linux), and writes them to
``$NNQL_TRACE/<process>.json`` when it ends. A step that sends something is marked as it is
handed to Zenoh, so a receiver never marks a message in before its sender marked it out. Off, a mark is a call that does nothing.
"""

import json
import os
import time
from pathlib import Path

TRACE_ENV = "NNQL_TRACE"

# The world's steps.
CLOSE = "close"  # the tick's last intent is in (or its deadline passed): the tick closes
OBS_SENT = "obs-sent"  # one observation of the tick is handed to Zenoh

# An agent's steps.
OBS_IN = "obs-in"  # its observation arrived
ANSWER_IN = "answer-in"  # an answer for the tick arrived (marked with its sender)
DECIDE = "decide"  # it starts deciding
ACTED = "acted"  # the learner chose the action
ENCODED = "encoded"  # the answer to the agents below is encoded: replying starts
ANSWERED = "answered"  # the standing queries owed are answered
INTENT_SENT = "intent-sent"  # the intent for the world is handed to Zenoh


class TickTrace:
    """One process's marks, kept in memory and written once when the process ends."""

    def __init__(self, name: str, directory: str | os.PathLike | None) -> None:
        self.path = Path(directory) / f"{name}.json" if directory else None
        self.on = self.path is not None
        self.marks: list[tuple[str, int, float] | tuple[str, int, float, int]] = []

    @classmethod
    def from_env(cls, name: str) -> "TickTrace":
        return cls(name, os.environ.get(TRACE_ENV) or None)

    def now(self) -> float:
        """The time to mark a step with later, once its tick is known (0 when off)."""
        return time.perf_counter() if self.on else 0.0

    def mark(self, step: str, tick: int, at: float | None = None,
             peer: int | None = None) -> None:
        """Mark ``step`` of ``tick`` as taken now (or ``at`` a time from :meth:`now`); ``peer``:
        the agent a message came from, where it matters (an answer)."""
        if self.on:
            at = time.perf_counter() if at is None else at
            self.marks.append((step, tick, at) if peer is None else (step, tick, at, peer))

    def save(self) -> None:
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self.path.write_text(json.dumps(self.marks))
