"""The paper's QL on a run's own settings, as a reference line under the run's learning curves.

With ``--reference`` the launcher plays the run's settings again with the paper's QL (the
``ql`` preset: independent Q-learning, no negotiation), in this process on the compiled
simulator, nothing written but its curves: ``metrics/<curve>/paper_ql`` for each curve of
:data:`CURVES`, on the ``episode`` timeline, into the run's recording (a part of its own). The
learning curves' plots show them beside the run's own, in grey. The same seed draws the same
starts and goals, so both play the same episodes.
"""

from dataclasses import replace

import numpy as np
import rerun as rr

from nnql_swarm.protocol.config import PRESETS, SwarmConfig

REFERENCE = "ql"
"""The preset whose curves are the reference: the paper's QL."""

NAME = "paper's QL, same settings"
COLOUR = (150, 150, 150)

CURVES = {
    "metrics/arrived_share/paper_ql": lambda e, n: e.arrived[0] / n,
    "metrics/steps/paper_ql": lambda e, n: e.agent_steps[0] / np.maximum(e.shortest[0], 1),
    "metrics/collisions/per_episode/paper_ql": lambda e, n: e.collisions[0].astype(float),
}
"""Each reference series, as the run's own curve of the same plot computes it from a row."""


def reference_config(config: SwarmConfig) -> SwarmConfig:
    """The run's settings with the paper's QL learning options."""
    return replace(config, **PRESETS[REFERENCE], run_id=f"{config.run_id}-paper-ql")


def play_reference(config: SwarmConfig) -> dict[str, np.ndarray]:
    """Every episode of the reference run (:func:`reference_config`), as :data:`CURVES`."""
    from nnql_swarm.sim.runs import Batch, Episodes, swarm_world

    reference = reference_config(config)
    batch = Batch(swarm_world(reference), [reference], record=False)
    results = batch.play(reference.episodes, Episodes(1, reference.episodes))
    return {path: np.asarray(curve(results, config.n_agents), dtype=np.float64)
            for path, curve in CURVES.items()}


def log_reference(config: SwarmConfig, stream: rr.RecordingStream) -> None:
    """Play the reference and log its curves into ``stream`` (which this closes)."""
    from nnql_swarm.recording.sinks import close_stream

    episodes = np.arange(config.episodes)
    for path, values in play_reference(config).items():
        stream.log(path, rr.SeriesLines(names=NAME, colors=[COLOUR], widths=1.5), static=True)
        stream.send_columns(path, [rr.TimeColumn("episode", sequence=episodes[:len(values)])],
                            rr.Scalars.columns(scalars=values))
    close_stream(stream)
