"""Where a stopped run continues (``--resume``): after its last complete episode, checkpoints checked.

The run's own ``config.json`` is the config; ``episodes.csv`` (a half-written last line dropped)
gives the last complete episode and the tick it ended on. Every checkpoint of the agents that
will run, and the world's shared table where the agents share one, is loaded once up front, so a
missing, corrupt or foreign one is refused before anything starts.
"""

from dataclasses import dataclass
from pathlib import Path

from nnql_swarm.agent import checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE
from nnql_swarm.world import checkpoint as world_checkpoint
from nnql_swarm.world.metrics import drop_partial_line, read_episodes


class ResumeError(ValueError):
    """The run directory cannot be resumed; the message says why and names the file."""


@dataclass(frozen=True)
class ResumePoint:
    """The first episode and tick of the continued run."""

    episode: int
    tick: int


def resume_point(out: Path) -> tuple[SwarmConfig, ResumePoint]:
    """The run's config and where it continues; raises ResumeError."""
    config_file = Path(out) / CONFIG_FILE
    if not config_file.is_file():
        raise ResumeError(f"{config_file}: no run to resume here")
    try:
        config = SwarmConfig.from_json(config_file.read_text())
    except (ValueError, TypeError) as error:
        raise ResumeError(f"{config_file}: not a valid run config ({error})") from None
    episodes_file = Path(out) / EPISODES_FILE
    drop_partial_line(episodes_file)
    rows = read_episodes(episodes_file) if episodes_file.exists() else []
    try:
        numbers = [int(row["episode"]) for row in rows]
        last_tick = int(rows[-1]["end_tick"]) if rows else -1
    except (KeyError, ValueError, TypeError) as error:
        raise ResumeError(f"{episodes_file}: unreadable row ({error})") from None
    if numbers != list(range(len(numbers))):
        raise ResumeError(f"{episodes_file}: episodes are not 0, 1, 2, ... in order")
    return config, ResumePoint(episode=len(numbers), tick=last_tick + 1)


def check_checkpoints(out: Path, config: SwarmConfig, agents: list[int]) -> None:
    """Load each agent's checkpoint into a scratch brain; raises ResumeError naming the file."""
    for agent in agents:
        path = checkpoint.checkpoint_path(Path(out) / CHECKPOINT_DIR, agent)
        if path.exists():
            try:
                checkpoint.load(path, AgentBrain(agent, config))
            except checkpoint.CheckpointError as error:
                raise ResumeError(str(error)) from None


def shared_table(out: Path, config: SwarmConfig, start: ResumePoint):
    """The shared ``(Q_DS, Q_CA)`` the world of a resumed run starts from (None where the agents
    learn apart, or nothing was learned yet, or nothing is left to play); raises ResumeError
    naming the file."""
    if not config.shared or not 0 < start.episode < config.episodes:
        return None
    try:
        return world_checkpoint.load(world_checkpoint.table_path(out), config, start.episode - 1)
    except checkpoint.CheckpointError as error:
        raise ResumeError(str(error)) from None
