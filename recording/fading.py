"""Paths faded by age: in a crowded run's episode view (``recording.agent_entities.CROWDED_FROM``)
each step of an agent's path is drawn the fainter the longer ago it was, so that where the
agents went last reads over where they went first.

A step's age is counted back from the newest step of its episode that the recording has sent
with it (the episode's end, once it has ended: the world sends what it holds at every
episode's end). The newest :data:`FRESH_STEPS` steps are opaque; older ones fade linearly to
:data:`OLDEST_ALPHA` at the episode's first step.
"""

import numpy as np

FRESH_STEPS = 16
"""The newest steps of an episode drawn opaque."""
OLDEST_ALPHA = 40
"""The opacity (of 255) of an episode's first step, where it is older than :data:`FRESH_STEPS`."""


def path_alpha(steps: np.ndarray, episodes: np.ndarray) -> np.ndarray:
    """The opacity (``uint8``) of each tick's step, ``steps[i]`` steps into episode
    ``episodes[i]``: 255 for the newest :data:`FRESH_STEPS` of each episode among these ticks,
    then down to :data:`OLDEST_ALPHA` at the first step."""
    steps, episodes = np.asarray(steps, np.int64), np.asarray(episodes, np.int64)
    newest = np.zeros(len(steps), np.int64)
    for episode in np.unique(episodes):
        here = episodes == episode
        newest[here] = steps[here].max()
    age = newest - steps
    fading = np.maximum(newest - FRESH_STEPS + 1, 1)  # the steps over which it fades
    share = np.clip((age - FRESH_STEPS + 1) / fading, 0.0, 1.0)
    return np.round(255 - share * (255 - OLDEST_ALPHA)).astype(np.uint8)
