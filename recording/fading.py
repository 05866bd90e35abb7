"""Paths faded by age: in a crowded run's episode view (``recording.agent_entities.CROWDED_FROM``)
each agent's path of the episode is drawn once, at the episode's end, in a few bands of its
colour, the older the fainter, so that where the agents went last reads over where they went
first.

Each agent's path runs to its last move; its newest :data:`FRESH_STEPS` steps are one opaque
band, the steps before them are split into :data:`BANDS` bands, from :data:`OLDEST_ALPHA` (the
episode's first steps) up. A few strips an
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


def moved_steps(cells: np.ndarray) -> np.ndarray:
    """For each agent, the steps of ``cells`` ``(steps + 1, n, 2)`` up to its last move (0: it
    never moved): an agent that arrived early and stood still has its own newest steps."""
    moved = np.any(np.diff(cells, axis=0) != 0, axis=2)  # (steps, n)
    last = len(moved) - np.argmax(moved[::-1], axis=0)
    return np.where(moved.any(axis=0), last, 0)


def route_strips(cells: np.ndarray) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
    """Every agent's path of an episode in bands, from ``cells`` ``(steps + 1, n, 2)`` (where
    each agent stood at each tick, the end's included), each up to its last move
    (:func:`moved_steps`): ``(agents, strips, alphas)``, one item per agent and band, agent by
    agent, oldest band first."""
    agents, strips, alphas = [], [], []
    for agent, steps in enumerate(moved_steps(cells).tolist()):
        for first, last, alpha in route_bands(steps):
            agents.append(agent)
            strips.append(np.ascontiguousarray(cells[first:last + 1, agent]))
            alphas.append(alpha)
    return np.array(agents, np.int64), strips, np.array(alphas, np.uint8)
