"""Paths faded by age: in a crowded run's episode view (``recording.agent_entities.CROWDED_FROM``)
each agent's path of the episode is drawn once, at the episode's end, in a few bands of its
colour, the older the fainter, so that where the agents went last reads over where they went
first.

The newest :data:`FRESH_STEPS` steps are one opaque band; the steps before them are split into
:data:`BANDS` bands, from :data:`OLDEST_ALPHA` (the episode's first steps) up. A few strips an
agent an episode, not one a step and agent: fewer things for the viewer to draw.
"""

import numpy as np

FRESH_STEPS = 16
"""The newest steps of an episode, drawn opaque."""
BANDS = 3
"""The bands the older steps are split into."""
OLDEST_ALPHA = 40
"""The opacity (of 255) of the oldest band."""


def route_bands(steps: int) -> list[tuple[int, int, int]]:
    """The bands of an episode path of ``steps`` steps (``steps + 1`` cells), oldest first:
    ``(first, last, alpha)``, the cells ``first`` to ``last`` (each band shares its first cell
    with the one before it) and the band's opacity."""
    older = max(steps - FRESH_STEPS, 0)
    cuts = np.unique(np.linspace(0, older, BANDS + 1).round().astype(int)).tolist()
    bands = [(first, last, round(OLDEST_ALPHA + (255 - OLDEST_ALPHA) * b / BANDS))
             for b, (first, last) in enumerate(zip(cuts, cuts[1:]))]
    return [*bands, (older, steps, 255)] if steps > 0 else []


def route_strips(cells: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Every agent's path of an episode in bands, from ``cells`` ``(steps + 1, n, 2)`` (where
    each agent stood at each tick, the end's included): ``(agents, strips, alphas)``, one item
    per agent and band, agent by agent, oldest band first."""
    bands = route_bands(len(cells) - 1)
    n = cells.shape[1]
    agents = np.repeat(np.arange(n), len(bands))
    strips = [np.ascontiguousarray(cells[first:last + 1, agent])
              for agent in range(n) for first, last, _ in bands]
    alphas = np.tile(np.array([alpha for _, _, alpha in bands], np.uint8), n)
    return agents, strips, alphas
