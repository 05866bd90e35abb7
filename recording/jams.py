"""Where the traffic jams are: per episode, how many steps agents on their way spent waiting on
each cell, drawn as a heat map under the agents (``world/jams``, on the episode's last tick).

An agent *waits* on a step when it is on its way (one-shot: not yet arrived; lifelong: always,
it always has a goal) and ends the step on the cell it started it on: it stayed, was blocked, or
was refused its move. Each such step adds one to its cell. Pure counting; the recorder
(``recording.world``) feeds it every tick and logs what :meth:`JamMap.take` returns.
"""

import numpy as np

JAM_COLOUR = (220, 40, 30)
"""The heat map's colour; its opacity grows with the steps waited on a cell."""

JAM_HALF, JAM_LINE = 0.25, 0.26
"""Each cell's box, its half-size and its outline's radius: an outline wider than the box fills
it, so the box covers the cell (as the walls are drawn, ``recording.world``)."""

MIN_ALPHA, MAX_ALPHA = 40, 200
"""The opacity of a cell waited on once, and of the episode's most waited-on cell."""


class JamMap:
    """The current episode's steps waited per cell, ``(height, width)``."""

    def __init__(self, width: int, height: int) -> None:
        self.waits = np.zeros((height, width), dtype=np.int64)

    def add(self, before: tuple, after: tuple, on_way: tuple) -> None:
        """One step: every agent's cell before and after it, and whether it was on its way."""
        for (x, y), cell, going in zip(before, after, on_way):
            if going and cell == (x, y):
                self.waits[y, x] += 1

    def take(self) -> tuple[np.ndarray, np.ndarray]:
        """The episode's map as boxes to draw, and start the next: the centres ``(K, 2)`` of
        the cells waited on and their RGBA colours ``(K, 4)``, most waited on last (drawn on
        top)."""
        ys, xs = np.nonzero(self.waits)
        counts = self.waits[ys, xs]
        order = np.argsort(counts, kind="stable")
        xs, ys, counts = xs[order], ys[order], counts[order]
        self.waits[:] = 0
        top = max(int(counts.max()), 1) if len(counts) else 1
        alpha = MIN_ALPHA + (MAX_ALPHA - MIN_ALPHA) * np.sqrt((counts - 1) / max(top - 1, 1))
        colours = np.empty((len(counts), 4), dtype=np.uint8)
        colours[:, :3] = JAM_COLOUR
        colours[:, 3] = np.round(alpha).astype(np.uint8)
        return np.column_stack([xs, ys]).astype(np.float32), colours
