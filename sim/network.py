"""A seeded network of simulated processes in virtual time: events, links and their faults.

Time only moves from one event to the next (a heap ordered by time, then by the order events
were made, so that equal times keep their order): a run takes as long as its events take to
handle, whatever virtual time passes. Every random draw comes from the one generator the
network is given.

A message sent from one :class:`Process` to another arrives after a latency drawn uniformly
from ``latency``, in order on each link (TCP's order, which Zenoh keeps), unless the network is
told to misbehave for a while:

- ``drop``: each message is lost with this probability;
- ``duplicate``: each message arrives twice with this probability (the copy a little later);
- ``reorder``: each message is held back by up to ``reorder_s`` with this probability,
  so that later messages on its link overtake it (except where the sender says what it must
  not overtake: a query's end never overtakes its replies, as in Zenoh);
- ``cut``: a partition: no message crosses between the processes named in it and the others.

:meth:`Network.send_reliable` carries what Zenoh carries reliably whatever the faults above
(liveliness changes): latency and order only. A message that arrives at a process that is gone,
or is no longer the incarnation it was sent to, is lost; one that arrives while its process is
stalled waits, in order, until the stall ends.
"""

import heapq
import random
from collections import Counter
from typing import Callable


class Process:
    """One simulated OS process: alive or not (which incarnation), maybe stalled until some
    time, with what arrived meanwhile waiting in order."""

    __slots__ = ("name", "incarnation", "alive", "stalled_until", "waiting", "timer_at")

    def __init__(self, name: str) -> None:
        self.name = name
        self.incarnation = 0
        self.alive = False
        self.stalled_until = 0.0
        self.waiting: list[tuple[Callable, tuple]] = []
        self.timer_at: float | None = None

    def __repr__(self) -> str:
        return f"Process({self.name}#{self.incarnation}{'' if self.alive else ', gone'})"


class Network:
    """The event loop and the links between processes (see the module docstring)."""

    def __init__(self, rng: random.Random, latency: tuple[float, float]) -> None:
        self.rng = rng
        self.now = 0.0
        self.events = 0
        self.halted = False
        self._heap: list = []
        self._made = 0
        self._low, self._span = latency[0], latency[1] - latency[0]
        self._last: dict[tuple[Process, Process], float] = {}  # each link's latest arrival
        self.drop = 0.0
        self.duplicate = 0.0
        self.reorder = 0.0
        self.reorder_s = 0.0
        self.cut: frozenset[str] | None = None
        self.sent = self.lost = 0
        self.sent_by: Counter[str] = Counter()  # messages sent (lost or not), by what they call

    def at(self, time: float, function: Callable, *args) -> None:
        """Call ``function(*args)`` at virtual ``time``."""
        self._made += 1
        heapq.heappush(self._heap, (time, self._made, function, args))

    def latency(self) -> float:
        return self._low + self._span * self.rng.random()

    def send(self, src: Process, dst: Process, function: Callable, *args,
             not_before: float = 0.0) -> float:
        """Carry a message from ``src`` to ``dst``, whose arrival calls ``function(*args)``;
        it arrives no sooner than ``not_before`` (what it must not overtake). Returns when it
        arrives (0.0 if lost)."""
        self.sent += 1
        self.sent_by[function.__name__] += 1
        cut = self.cut
        if cut is not None and (src.name in cut) != (dst.name in cut):
            self.lost += 1
            return 0.0
        rng = self.rng
        if self.drop and rng.random() < self.drop:
            self.lost += 1
            return 0.0
        arrival = self.now + self._low + self._span * rng.random()
        if arrival < not_before:
            arrival = not_before
        if self.reorder and rng.random() < self.reorder:
            arrival += self.reorder_s * rng.random()  # later messages may overtake it
        else:
            arrival = self._in_order(src, dst, arrival)
        self._deliver(dst, arrival, function, args)
        if self.duplicate and rng.random() < self.duplicate:
            self._deliver(dst, arrival + self.latency(), function, args)
        return arrival

    def send_reliable(self, src: Process | None, dst: Process, function: Callable, *args) -> None:
        """Like :meth:`send`, but only latency and order apply (``src`` None: from the network
        itself, e.g. a liveliness change it noticed)."""
        arrival = self.now + self._low + self._span * self.rng.random()
        if src is not None:
            arrival = self._in_order(src, dst, arrival)
        self._deliver(dst, arrival, function, args)

    def _in_order(self, src: Process, dst: Process, arrival: float) -> float:
        """``arrival``, or later: nothing overtakes the message before it on its link."""
        link = (src, dst)
        last = self._last.get(link, 0.0)
        if arrival < last:
            arrival = last
        self._last[link] = arrival
        return arrival

    def _deliver(self, dst: Process, arrival: float, function: Callable, args: tuple) -> None:
        self._made += 1
        heapq.heappush(self._heap, (arrival, self._made, self._arrive,
                                    (dst, dst.incarnation, function, args)))

    def local(self, process: Process, delay: float, function: Callable, *args) -> None:
        """Something that happens inside ``process`` after ``delay`` (a time-out of its own): it
        waits if the process is stalled then, and is lost if the process is gone."""
        self._made += 1
        heapq.heappush(self._heap, (self.now + delay, self._made, self._arrive,
                                    (process, process.incarnation, function, args)))

    def _arrive(self, dst: Process, incarnation: int, function: Callable, args: tuple) -> None:
        if not dst.alive or dst.incarnation != incarnation:
            return
        if dst.stalled_until > self.now:
            dst.waiting.append((function, args))
            return
        function(*args)

    def stall(self, process: Process, duration: float, resumed: Callable) -> None:
        """Stop ``process`` for ``duration``: what arrives meanwhile waits; then it handles all
        of it in order, and ``resumed(process)`` is called."""
        until = self.now + duration
        if not process.alive or until <= process.stalled_until:
            return
        process.stalled_until = until
        self.at(until, self._unstall, process, process.incarnation, resumed)

    def _unstall(self, process: Process, incarnation: int, resumed: Callable) -> None:
        if (not process.alive or process.incarnation != incarnation
                or process.stalled_until > self.now):
            return
        waiting, process.waiting = process.waiting, []
        for function, args in waiting:
            if not process.alive or process.incarnation != incarnation:
                return
            function(*args)
        if process.alive and process.incarnation == incarnation:
            resumed(process)

    def run(self, until: float, max_events: int) -> bool:
        """Handle events in time order until none is left, :attr:`halted` is set, virtual time
        passes ``until`` or ``max_events`` were handled; True if it ended by itself (no events
        left, or halted)."""
        heap, pop = self._heap, heapq.heappop
        events = self.events
        try:
            while heap and not self.halted:
                time, _, function, args = pop(heap)
                if time > until or events >= max_events:
                    return False
                self.now = time
                events += 1
                function(*args)
        finally:
            self.events = events
        return True
