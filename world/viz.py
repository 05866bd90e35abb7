"""The world's Rerun recording: grid, agents, goals, intents, collisions and metrics per tick.

Entity paths are stable (``world/agents``, ``world/goals``, ``metrics/collisions``); timelines are
``tick`` and ``episode``. Every process of a run logs into the recording whose id is the run id.
"""

from pathlib import Path

import numpy as np
import rerun as rr

from protocol.actions import MOVES
from protocol.config import SwarmConfig
from world.engine import SwarmWorld, TickReport

APP_ID = "nnql-swarm"


def agent_colors(n: int) -> np.ndarray:
    """One distinct colour per agent (evenly spaced hues), as RGB bytes ``(n, 3)``."""
    hues = np.arange(n) / max(n, 1)
    k = (np.array([5.0, 3.0, 1.0])[None, :] + hues[:, None] * 6.0) % 6.0
    rgb = 1.0 - np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)
    return (rgb * 255).astype(np.uint8)


class WorldViz:
    """Logs a swarm run, tick by tick, into one Rerun recording stream."""

    def __init__(self, config: SwarmConfig, stream: rr.RecordingStream) -> None:
        self.config = config
        self.rec = stream
        self.colors = agent_colors(config.n_agents)
        self.labels = [str(i) for i in range(config.n_agents)]
        self.cumulative_collisions = 0
        self._log_static()

    @staticmethod
    def to_file(config: SwarmConfig, path: Path) -> "WorldViz":
        stream = rr.RecordingStream(APP_ID, recording_id=config.run_id)
        stream.save(str(path))
        return WorldViz(config, stream)

    def _log_static(self) -> None:
        c = self.config
        xs = np.arange(c.width + 1) - 0.5
        ys = np.arange(c.height + 1) - 0.5
        lines = [[(x, ys[0]), (x, ys[-1])] for x in xs] + [[(xs[0], y), (xs[-1], y)] for y in ys]
        self.rec.log("world/grid", rr.LineStrips2D(lines, colors=[80, 80, 80], radii=0.02), static=True)

    def log_tick(self, world: SwarmWorld, report: TickReport) -> None:
        rec = self.rec
        rec.set_time("tick", sequence=report.tick)
        rec.set_time("episode", sequence=report.episode)
        positions = world.positions.astype(np.float32)
        rec.log("world/agents", rr.Points2D(positions, colors=self.colors, labels=self.labels, radii=0.35))
        rec.log("world/goals", rr.Boxes2D(centers=world.goals, sizes=[[0.8, 0.8]], colors=self.colors))
        moves = MOVES[list(report.actions)].astype(np.float32)
        rec.log("world/intents", rr.Arrows2D(origins=positions, vectors=moves * 0.8, colors=self.colors))
        if report.collided:
            cells = world.positions[list(report.collided)]
            rec.log("world/collisions", rr.Points2D(cells, colors=[255, 0, 0], radii=0.5))
            rec.log("events", rr.TextLog(
                f"tick {report.tick}: collision of agents {list(report.collided)}",
                level=rr.TextLogLevel.WARN))
        else:
            rec.log("world/collisions", rr.Clear(recursive=False))
        if report.episode_row is not None:
            row = report.episode_row
            self.cumulative_collisions += row["collisions"]
            rec.log("metrics/collisions", rr.Scalars(row["collisions"]))
            rec.log("metrics/cumulative_collisions", rr.Scalars(self.cumulative_collisions))
            rec.log("metrics/steps", rr.Scalars(row["steps"]))
            rec.log("metrics/missed_intents", rr.Scalars(row["missed_intents"]))
            rec.log("metrics/reward_sum", rr.Scalars(row["reward_sum"]))
            rec.log("events", rr.TextLog(f"episode {row['episode']} done: {row}"))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()
