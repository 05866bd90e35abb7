"""The shared table's entries that each quiet agent has not heard of (``world.engine``): exact,
and at a cost a tick that does not grow with the quiet agents. Pure.

A quiet agent is sent no observation, so every tick's updates are entries it misses; it is sent
one again once :attr:`UnheardEntries.catch_up` distinct entries wait, with their current values.
An agent is quiet at every tick from the one it went quiet at to its next observation, so what it
missed is every entry changed at a tick of that stretch. The ticks at which anyone is quiet are
logged (:meth:`~UnheardEntries.log_tick`) with, for every entry, the last logged tick that
changed it, and how many entries each logged tick was the last to change: how many an agent
missed is how many were last changed at or after the tick it went quiet, one lookup a tick,
where a set of its own took in every entry of every tick. Only an agent that leaves the quiet
while others stay (a restarted one, sent the whole table) has its entries read back from the log.
"""

from itertools import accumulate

import numpy as np

from nnql_swarm.protocol.messages import unpack_group

Groups = tuple[tuple[bytes, bytes], ...]
"""A tick's updates as packed groups (``protocol.messages.pack_updates``)."""


class UnheardEntries:
    """What each quiet agent missed, from the tick it went quiet to its next observation; for a
    table of ``entries`` entries."""

    def __init__(self, catch_up: int, entries: int) -> None:
        self.catch_up = catch_up
        self._entries = entries
        self.clear()

    def clear(self) -> None:
        """Nobody is quiet any more (a new episode starts): forget the log."""
        self._log: list[Groups] = []  # each logged tick's updates, in order
        self._last = np.full(self._entries, -1, dtype=np.int64)  # entry -> last logged tick
        self._lasts: list[int] = []  # logged tick -> entries it changed last
        self._since: list[int] = []  # logged tick -> entries changed at it or later
        self._quiet: dict[int, list[int]] = {}  # agent -> [first, last] logged tick it is quiet

    def log_tick(self, updates: Groups) -> None:
        """This tick's updates, missed by the agents quiet at it (:meth:`quiet`)."""
        if not self._quiet and self._log:  # nobody misses what was logged before
            self.clear()
        tick, lasts = len(self._log), self._lasts
        self._log.append(updates)
        changed: set[int] = set()
        for group in updates:
            changed.update(unpack_group(group)[0].tolist())
        entries = np.fromiter(changed, dtype=np.int64, count=len(changed))
        for before in self._last[entries].tolist():
            if before >= 0:
                lasts[before] -= 1
        lasts.append(len(changed))
        self._last[entries] = tick
        self._since = list(accumulate(reversed(lasts)))[::-1]

    def quiet(self, agent: int) -> bool:
        """``agent`` is quiet at the tick logged last: whether it is to stay so (fewer than
        :attr:`catch_up` entries wait for it)."""
        tick = len(self._log) - 1
        stretch = self._quiet.get(agent)
        if stretch is None:
            stretch = self._quiet[agent] = [tick, tick]
        stretch[1] = tick
        return self._since[stretch[0]] < self.catch_up

    def pop(self, agent: int) -> list[int]:
        """The entries ``agent`` missed, in order, which its observation now brings: it has
        heard them."""
        stretch = self._quiet.pop(agent, None)
        if stretch is None:
            return []
        first, last = stretch
        if last == len(self._log) - 1:  # quiet until the tick logged last: no later change
            return np.flatnonzero(self._last >= first).tolist()
        missed: set[int] = set()  # it left the quiet while others stayed: read the log back
        for updates in self._log[first:last + 1]:
            for group in updates:
                missed.update(unpack_group(group)[0].tolist())
        return sorted(missed)
