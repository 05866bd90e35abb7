"""Where every random draw comes from: generators derived from the run's seed, one per stream.

``SeedSequence(seed, spawn_key=(stream, index))`` gives independent, reproducible streams: the
scenario of episode ``index``, or the noise of agent ``index``. Nothing else draws randomness.
"""

import numpy as np

SCENARIO_STREAM = 1
AGENT_STREAM = 2


def stream_rng(seed: int, stream: int, index: int) -> np.random.Generator:
    """The generator of one stream of a run."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream, index)))
