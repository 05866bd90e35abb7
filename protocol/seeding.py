"""Where every random draw comes from: generators derived from the run's seed, one per stream.

``SeedSequence(seed, spawn_key=(stream, index))`` gives independent, reproducible streams: the
scenario of episode ``index``, the noise of agent ``index``, or (the simulator, ``sim``) a fault
schedule's draws; an agent's goals in an episode of a lifelong run (:func:`task_rng`); and, once
per run, its walls (``protocol.walls``) or its generated map
(``world.terrain``). Nothing else draws randomness.
"""

import numpy as np

SCENARIO_STREAM = 1
AGENT_STREAM = 2
SIM_STREAM = 3
WALL_STREAM = 4
MAP_STREAM = 5
TASK_STREAM = 6


def stream_rng(seed: int, stream: int, index: int) -> np.random.Generator:
    """The generator of one stream of a run."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(stream, index)))


def task_rng(seed: int, episode: int, agent: int) -> np.random.Generator:
    """The generator of one agent's goals in one episode of a lifelong run (``--tasks
    lifelong``): its own stream, so that the goals an agent is given depend on the run's seed, the
    episode and the agent alone, and a resumed run draws them again as they were."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(TASK_STREAM, episode,
                                                                         agent)))
