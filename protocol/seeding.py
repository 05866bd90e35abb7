"""Where every random draw comes from: generators derived from the run's seed, one per stream.

``SeedSequence(seed, spawn_key=(stream, index))`` gives independent, reproducible streams: the
scenario of episode ``index``, the noise of agent ``index``, or (the simulator, ``sim``) a fault
schedule's draws; and, once per run, its walls (``protocol.walls``) or its generated map
(``terrain.maps``). Nothing else draws randomness.
"""

import numpy as np

SCENARIO_STREAM = 1
AGENT_STREAM = 2
SIM_STREAM = 3
WALL_STREAM = 4
MAP_STREAM = 5


def stream_rng(seed: int, stream: int, index: int) -> np.random.Generator:
    """The generator of one stream of a run."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream, index)))
