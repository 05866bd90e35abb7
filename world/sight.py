"""Whom every agent sees at a tick, packed as the observations carry it: one kernel pass over
the agents' cells (``protocol.actions.sees`` between every two), compiled ahead of time with the
world's step where it is built (``world.rules_ahead``).

:func:`pack_seen` writes every agent's visible others ``(id, x, y)`` in id order, and the ids of
those of them that are parked, one agent after the other, as the wire packs them
(``protocol.messages.pack_neighbours``, ``pack_ids``: 16-bit integers), and where each agent's
part starts, in bytes. The world makes one ``bytes`` of each packing a tick and hands each agent
its slices (``world.engine``).
"""

from nnql_swarm.protocol.actions import sees
from nnql_swarm.protocol.jit import kernel
from nnql_swarm.protocol.messages import CELL_TYPE, NEIGHBOUR_ITEMS

ITEM_BYTES = CELL_TYPE.itemsize
"""The bytes of one packed integer (an id, or a coordinate)."""


@kernel
def pack_seen(xs, ys, arrived, n, sees_all, parks, seen, parked, seen_at, parked_at):
    """For each of the ``n`` agents at cells ``(xs[i], ys[i])``: the others it sees (every
    other where ``sees_all``: the grid fits in the view) as ``(id, x, y)`` in id order, into
    ``seen``; where arrived agents park (``parks``), the ids of those of them that have
    ``arrived``, into ``parked``; agent ``i``'s part of each from byte ``seen_at[i]`` to
    ``seen_at[i + 1]`` (``parked_at`` likewise). Buffers hold ``n * (n - 1)`` neighbours."""
    s = 0
    q = 0
    seen_at[0] = 0
    parked_at[0] = 0
    for i in range(n):
        for j in range(n):
            if j == i or not (sees_all or sees(xs[i], ys[i], xs[j], ys[j])):
                continue
            seen[s] = j
            seen[s + 1] = xs[j]
            seen[s + 2] = ys[j]
            s += NEIGHBOUR_ITEMS
            if parks and arrived[j]:
                parked[q] = j
                q += 1
        seen_at[i + 1] = s * ITEM_BYTES
        parked_at[i + 1] = q * ITEM_BYTES


SEEN_SIGNATURE = "void(i8[::1], i8[::1], b1[::1], i8, b1, b1, u2[::1], u2[::1], i8[::1], i8[::1])"
""":func:`pack_seen`'s types, as compiled ahead of time."""
