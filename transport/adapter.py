"""What the agent and world nodes share as adapters of their protocol machines.

A node feeds each input to its machine under the node's one lock and carries out the effects it
returns there, in order; its main thread takes the node's queue of events and fires the
machine's timer (:class:`ProtocolAdapter`).
"""

import queue
import signal
import threading
import time
from typing import Callable, Protocol

POLL_S = 0.05
"""The longest a node's main thread sleeps on its queue: a timer set meanwhile on Zenoh's thread
(a tick's deadline, a negotiation's time-out) is noticed at most this late, and so is a request
to stop."""


class Machine(Protocol):
    """A protocol machine as its node's main thread drives it: its timer."""

    def timer(self) -> float | None:
        """When :meth:`on_timer` is next due (None: no timer)."""

    def on_timer(self, now: float) -> list:
        """Time has come to ``now``: the effects."""


class ProtocolAdapter:
    """The base of the agent and world nodes: an input is fed under the node's one lock and its
    effects are carried out there, in order, each by the handler ``_do`` names for its type. A
    bug in either stops the node (its ``run`` re-raises ``failure`` on the main thread) instead
    of vanishing into Zenoh's thread. The main thread takes the node's queue of ``events``
    (:meth:`next_event`) and fires the protocol's timer (:meth:`fire_timer_if_due`).

    A node sets ``lock``, ``stopping``, ``failure``, ``protocol``, ``events`` and ``_do``, and
    says how it stops."""

    lock: threading.RLock
    stopping: bool
    failure: BaseException | None
    protocol: Machine  # a node declares the machine it drives
    events: queue.SimpleQueue
    _do: dict[type, Callable]

    def stop(self) -> None:
        raise NotImplementedError

    def feed(self, handler: Callable, *args) -> None:
        """``handler(*args, now)``, a protocol input, then its effects."""
        with self.lock:
            if self.stopping:
                return
            try:
                self.perform(handler(*args, time.monotonic()))
            except Exception as error:  # noqa: BLE001 - re-raised by run() on the main thread
                self.failure = error
                self.stop()

    def perform(self, effects: list) -> None:
        do = self._do
        for effect in effects:
            do[type(effect)](effect)

    def next_event(self) -> tuple:
        """The next ``(kind, item)`` of the main thread's queue; ``(None, None)`` if none came
        before the protocol's timer is due, or within :data:`POLL_S`."""
        with self.lock:
            due = self.protocol.timer()
        wait = POLL_S if due is None else min(max(due - time.monotonic(), 0.0), POLL_S)
        try:
            return self.events.get(timeout=wait)
        except queue.Empty:
            return None, None

    def fire_timer_if_due(self) -> None:
        """Feed the protocol its timer if that is due."""
        with self.lock:
            due = self.protocol.timer()
        if due is not None and time.monotonic() >= due:
            self.feed(self.protocol.on_timer)


def stop_on_signals(node: ProtocolAdapter) -> None:
    """SIGINT and SIGTERM stop ``node``: its main thread then winds it down."""
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: node.stop())
