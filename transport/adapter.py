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

CPU_SAMPLE_EVERY = 8
"""One input of each kind in this many is timed for :attr:`ProtocolAdapter.handler_cpu`: a
thread's CPU clock is a system call, and three of them an input were 5 to 6 % of the handlers'
CPU a tick (docs/performance.md, "What a handler may cost")."""

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

    What each input costs is kept as it goes (:attr:`handler_cpu`, :meth:`handler_cpu_stats`),
    sampled: its thread's CPU time in the machine and in carrying out the effects, which is what
    a process's handlers cost where it runs, on whatever caches it finds.

    A node sets ``lock``, ``stopping``, ``failure``, ``protocol``, ``events``, ``_do`` and
    ``handler_cpu`` (empty), and says how it stops."""

    lock: threading.RLock
    stopping: bool
    failure: BaseException | None
    protocol: Machine  # a node declares the machine it drives
    events: queue.SimpleQueue
    _do: dict[type, Callable]
    handler_cpu: dict[str, list]  # input -> [calls, calls timed, CPU s in the machine, in effects]

    def stop(self) -> None:
        raise NotImplementedError

    def run(self) -> object:
        """Drive the machine on the main thread until the node stops; what the run ends with."""
        raise NotImplementedError

    def feed(self, handler: Callable, *args) -> None:
        """``handler(*args, now)``, a protocol input, then its effects; one input of each kind
        in :data:`CPU_SAMPLE_EVERY` adds the CPU time each took to :attr:`handler_cpu`."""
        with self.lock:
            if self.stopping:
                return
            name = handler.__name__
            spent = self.handler_cpu.get(name)
            if spent is None:
                spent = self.handler_cpu[name] = [0, 0, 0.0, 0.0]
            spent[0] += 1
            try:
                if spent[0] % CPU_SAMPLE_EVERY:
                    self.perform(handler(*args, time.monotonic()))
                    return
                clock = time.thread_time
                started = clock()
                effects = handler(*args, time.monotonic())
                decided = clock()
                self.perform(effects)
                ended = clock()
            except Exception as error:  # noqa: BLE001 - re-raised by run() on the main thread
                self.failure = error
                self.stop()
                return
            spent[1] += 1
            spent[2] += decided - started
            spent[3] += ended - decided

    def handler_cpu_stats(self) -> dict[str, dict]:
        """What each input cost so far, for the process's stats: its calls, and the
        microseconds of its thread's CPU time a call took in the machine and in carrying out the
        effects, over the calls timed (``bench/tick_cpu.py`` prints them); None for an input
        fed fewer than :data:`CPU_SAMPLE_EVERY` times."""
        return {name: {"calls": calls,
                       "machine_us": round(1e6 * machine / timed, 1) if timed else None,
                       "effects_us": round(1e6 * effects / timed, 1) if timed else None}
                for name, (calls, timed, machine, effects) in sorted(self.handler_cpu.items())}

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
