"""The shared table's entries that each quiet agent has not heard of (``world.engine``): exact,
and cheap on the ticks where an agent stays quiet. Pure.

A quiet agent is sent no observation, so every tick's updates are entries it misses; it is sent
one again once :attr:`UnheardEntries.catch_up` distinct entries wait, with their current values.
Each tick's updates are logged once for all quiet agents (as the packed groups the observations
carry), and an agent's set takes them in only when they could bring it to the catch-up count:
its size plus every entry logged since counts each entry at most once more than it is. Until
then a quiet tick costs an agent a comparison, not a set update per entry; the set, and so when
the agent is sent an observation, is the same.
"""

from nnql_swarm.protocol.messages import ENTRY_TYPE, unpack_group

Groups = tuple[tuple[bytes, bytes], ...]
"""A tick's updates as packed groups (``protocol.messages.pack_updates``)."""


class UnheardEntries:
    """What each quiet agent missed, from the tick it went quiet to its next observation."""

    def __init__(self, catch_up: int) -> None:
        self.catch_up = catch_up
        self._log: list[Groups] = []  # each logged tick's updates, in order
        self._logged = [0]  # entries logged before each tick of the log, and after the last
        self._missed: dict[int, list] = {}  # agent -> [entries, log ticks taken in, missed]

    def log_tick(self, updates: Groups) -> None:
        """This tick's updates, missed by the agents quiet at it (:meth:`quiet`)."""
        if not self._missed:  # nobody misses what was logged before
            self.clear()
        self._log.append(updates)
        self._logged.append(self._logged[-1] + sum(len(entries) for entries, _ in updates)
                            // ENTRY_TYPE.itemsize)

    def quiet(self, agent: int) -> bool:
        """``agent`` is quiet at the tick logged last: whether it is to stay so (fewer than
        :attr:`catch_up` entries wait for it)."""
        missed = self._missed.get(agent)
        if missed is None:
            missed = self._missed[agent] = [set(), len(self._log) - 1, 0]
        missed[2] = len(self._log)
        entries, taken, through = missed
        if len(entries) + self._logged[through] - self._logged[taken] < self.catch_up:
            return True
        return len(self._take_in(missed)) < self.catch_up

    def pop(self, agent: int) -> set[int]:
        """The entries ``agent`` missed, which its observation now brings: it has heard them."""
        if agent not in self._missed:
            return set()
        return self._take_in(self._missed.pop(agent))

    def clear(self) -> None:
        """Nobody is quiet any more (a new episode starts): forget the log."""
        self._log, self._logged, self._missed = [], [0], {}

    def _take_in(self, missed: list) -> set[int]:
        """An agent's entries, with those of the ticks it missed since they were last taken in."""
        entries, taken, through = missed
        for updates in self._log[taken:through]:
            for group in updates:
                entries.update(unpack_group(group)[0].tolist())
        missed[1] = through
        return entries
