"""The swarm's one Q-table, as the world keeps it where the agents share it (``config.shared``).

Each agent's intent carries its learning record of the tick. The world checks that every record
fits the tables (:meth:`SharedTable.accepts`, as it takes the intent) and is the one the agent's
own transition wrote (``world.records``) and, when the tick closes, applies those it believes
in agent-id order with the learner's own ``apply_record`` (all of a tick's in one call of
``apply_records``, compiled ahead of time where it is built, ``learning.ahead``), the very step
the simulator applies to its one table (``sim.episode``). The next observations then tell every agent which entries
changed and their new values (:meth:`SharedTable.apply` returns them, in the order the records
wrote them), and each agent writes them into its copy (``learning.record.write_updates``). All
copies stay equal to this one and to the simulator's, and a tick costs every agent one write per
changed entry, where applying every record itself cost it the whole learning step N times over.

An agent whose copy may differ (it was restarted from an older checkpoint, or the world was
restarted under it from its own) is sent the whole table instead, a slice of it with each of its
observations (:meth:`SharedTable.chunk`): each slice holds the values as the tick's updates leave
them, and every later change reaches the agent as an update, so once the last slice is written
its copy equals this one.
"""

from typing import NamedTuple

import numpy as np

from nnql_swarm.learning import ahead
from nnql_swarm.learning.fields import FP_ALPHA, FP_GAMMA, RF_FIELDS
from nnql_swarm.learning.record import record_is_valid
from nnql_swarm.learning.tables import Learner
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import Buffer
from nnql_swarm.protocol.messages import pack_updates

Updates = tuple[tuple[bytes, bytes], ...]
"""Groups of packed entry indices and their new values (``protocol.messages.Updates``)."""


class SharedState(NamedTuple):
    """What the shared table's checkpoint holds (``world.world_checkpoint``): the tables as an
    episode's end tick found them, which every agent checkpointed then, and the learning records
    that tick brought (``(agent, integers, rewards)`` in agent-id order), which the next
    episode's first observations hand out applied."""

    q_ds: np.ndarray
    q_ca: np.ndarray
    records: tuple[tuple[int, tuple[int, ...], tuple[float, ...]], ...] = ()


class SharedTable:
    """The world's copy of the swarm's one table (see the module docstring)."""

    def __init__(self, config: SwarmConfig) -> None:
        self._learner = Learner(config)  # the tables an agent starts with, and its alpha, gamma
        self._apply, how = ahead.KERNELS.compiled("apply_records")
        self._arrays = how != ahead.PLAIN  # its buffers: arrays, else lists
        self.alpha = self._learner.params_f[FP_ALPHA]
        self.gamma = self._learner.params_f[FP_GAMMA]

    def accepts(self, record) -> bool:
        """Whether a record received from an agent fits the tables (a forged or mistaken one
        must never write outside them)."""
        integers, values = record
        return record_is_valid(integers, values, len(self._learner.q_ca))

    def apply(self, learned: dict[int, tuple]) -> Updates:
        """Apply the accepted records of a tick (``agent -> (integers, rewards)``) in agent-id
        order; the entries each one wrote, with their values once all are applied."""
        if not learned:
            return ()
        integers: list[int] = []
        starts: list[int] = [0]
        rewards: list[float] = []  # every record's, one after the other
        for agent in sorted(learned):
            record = learned[agent]
            integers += record[0]
            starts.append(len(integers))
            rewards += record[1]
        size = len(integers)  # a record writes fewer entries than its integers
        ints: Buffer
        floats: Buffer
        starts_: Buffer
        written: Buffer
        if self._arrays:  # made from flat lists: numpy reads nested ones several times slower
            ints, floats = np.array(integers, np.int64), np.array(rewards).reshape(-1, RF_FIELDS)
            starts_, written = np.array(starts, np.int64), np.zeros(size, np.int64)
        else:
            ints, starts_, written = integers, starts, [0] * size
            floats = [rewards[k:k + RF_FIELDS] for k in range(0, len(rewards), RF_FIELDS)]
        n = self._apply(self._learner.q_ds, self._learner.q_ca, ints, starts_, floats,
                        len(starts) - 1, self.alpha, self.gamma, written)
        return self.current(written[:n])

    @property
    def entries(self) -> int:
        """How many Q-values both tables hold (entry indices are 0 to this - 1)."""
        return len(self._learner.entries)

    def current(self, entries) -> Updates:
        """The current values of ``entries``, as update groups."""
        return pack_updates(entries, self._learner.entries[entries])

    def chunk(self, start: int, count: int) -> Updates:
        """The current values of entries ``start`` to ``start + count - 1`` (fewer at the end),
        as update groups."""
        stop = min(start + count, self.entries)
        return pack_updates(range(start, stop), self._learner.entries[start:stop])

    def tables(self) -> tuple[np.ndarray, np.ndarray]:
        """``Q_DS`` and ``Q_CA`` as arrays (copies)."""
        return self._learner.tables()

    def state(self, learned: dict[int, tuple]) -> SharedState:
        """The tables as they are (copies), with the records of a tick not yet applied
        (``agent -> (integers, rewards)``), for the world's checkpoint."""
        records = tuple((agent, tuple(learned[agent][0]), tuple(learned[agent][1]))
                        for agent in sorted(learned))
        return SharedState(*self._learner.tables(), records)

    def restore(self, q_ds: np.ndarray, q_ca: np.ndarray) -> None:
        """Take the tables of a checkpoint (shapes checked by the caller)."""
        self._learner.restore(q_ds, q_ca, 0)
