"""Where a stopped run continues (``--resume``): the last episode that every process made durable.

Every process writes its own files at each episode's end: an agent its checkpoint, before its
end tick's intent; the world the shared table's checkpoint, then the episode's row. Whatever
stopped the run, whenever, those files may stand at different episodes (a Ctrl-C can reach some
agents before they checkpoint an end tick and others after). Each checkpoint file keeps its
newest two versions (``transport.slotfile``), so a run has one consistent *cut*: the last episode
with a row in ``episodes.csv`` (a half-written last line dropped) and a checkpoint of it in every
file of the processes this launcher starts (a process with no file yet stands before episode
0: the run starts afresh). The resumed run starts every process from the cut's checkpoints; rows
past the cut are dropped and played again, to the same values.

A process that missed its end ticks (an agent partitioned, stalled or dead while the world went
on without it) may stand two episodes or more behind the others, past what their files keep:
then there is no cut, the run already differs from one left alone, and it continues as it
would have gone on, the world after its last row and every agent from its newest checkpoint,
with a warning naming the files that lag (:attr:`ResumePoint.lagging`). A corrupt or foreign
file is refused with one line naming it. The checks load every version the processes may load.
"""

from dataclasses import dataclass
from pathlib import Path

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.learning.saved import CheckpointError
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.metrics import COLUMNS, drop_partial_line, keep_rows, read_episodes
from nnql_swarm.world.shared_table import SharedState


class ResumeError(ValueError):
    """The run directory cannot be resumed; the message says why and names the file."""


@dataclass(frozen=True)
class ResumePoint:
    """The first episode and tick of the continued run, how many written rows it plays again
    (rows past the cut), and the files that lag behind any cut (none: the run resumes exactly)."""

    episode: int
    tick: int
    replayed: int = 0
    lagging: tuple[str, ...] = ()

    @property
    def cut(self) -> int:
        """The episode every process resumes after (-1: none, the run starts afresh)."""
        return self.episode - 1

    @property
    def exact(self) -> bool:
        return not self.lagging

    @property
    def checkpoint_episode(self) -> int | None:
        """The version of its checkpoint every agent loads (None: its newest)."""
        return self.cut if self.exact else None


def read_config(out: Path) -> SwarmConfig:
    """The run's ``config.json``; raises ResumeError naming the file."""
    config_file = Path(out) / CONFIG_FILE
    if not config_file.is_file():
        raise ResumeError(f"{config_file}: no run to resume here")
    try:
        return SwarmConfig.from_json(config_file.read_text())
    except (ValueError, TypeError) as error:
        raise ResumeError(f"{config_file}: not a valid run config ({error})") from None


def _rows(out: Path) -> list[dict]:
    """The complete rows of ``episodes.csv`` (episodes 0, 1, 2, ...); raises ResumeError."""
    episodes_file = Path(out) / EPISODES_FILE
    drop_partial_line(episodes_file)
    rows = read_episodes(episodes_file) if episodes_file.exists() else []
    header = episodes_file.read_text().partition("\n")[0] if episodes_file.exists() else ""
    if header and tuple(header.strip().split(",")) != COLUMNS:
        raise ResumeError(f"{episodes_file}: its columns are not this version's (written by "
                          "another version of nnql-swarm); start a new run in another folder")
    try:
        numbers = [int(row["episode"]) for row in rows]
        [int(row["end_tick"]) for row in rows]
    except (KeyError, ValueError, TypeError) as error:
        raise ResumeError(f"{episodes_file}: unreadable row ({error})") from None
    if numbers != list(range(len(numbers))):
        raise ResumeError(f"{episodes_file}: episodes are not 0, 1, 2, ... in order")
    return rows


def _agent_versions(out: Path, config: SwarmConfig, agent: int) -> tuple[Path, list[int]]:
    """An agent's checkpoint file and the episodes it holds, the newest first (none if there is
    no file); each version is loaded into a scratch brain, so a bad one is refused here."""
    path = agent_checkpoint.checkpoint_path(Path(out) / CHECKPOINT_DIR, agent)
    if not path.exists():
        return path, []
    try:
        return path, [agent_checkpoint.load(path, AgentBrain(agent, config), episode)
                      for episode in agent_checkpoint.episodes(path)]
    except CheckpointError as error:
        raise ResumeError(str(error)) from None


def _world_versions(out: Path, config: SwarmConfig) -> tuple[Path, list[int]]:
    """The shared table's checkpoint file and the episodes it holds, the newest first; each
    version is loaded, so a bad one (or another run's) is refused here."""
    path = world_checkpoint.table_path(out)
    if not path.exists():
        return path, []
    try:
        versions = world_checkpoint.episodes(path)
        for episode in versions:
            world_checkpoint.load(path, config, episode)
        return path, versions
    except CheckpointError as error:
        raise ResumeError(str(error)) from None


def resume_point(out: Path, agents: list[int], world: bool) -> tuple[SwarmConfig, ResumePoint]:
    """The run's config and its cut, over the rows (where this launcher runs the ``world``),
    the shared table's checkpoint (likewise, where the agents share one) and the checkpoints of
    ``agents``; raises ResumeError naming a file that cannot be used. Reads only."""
    config = read_config(out)
    rows = _rows(out) if world else []
    files = [_agent_versions(out, config, agent) for agent in agents]
    if world and config.shared:
        files.append(_world_versions(out, config))
    newest = [max(episodes, default=-1) for _, episodes in files]
    last_row = len(rows) - 1 if world else min(newest, default=-1)
    cut = min([last_row, *newest])
    lagging = tuple(f"{path} holds episodes {sorted(episodes)}, not {cut}"
                    for path, episodes in files if cut >= 0 and cut not in episodes)
    if lagging:  # no cut: everyone goes on from where it stands
        cut = last_row
    tick = int(rows[cut]["end_tick"]) + 1 if world and cut >= 0 else 0
    return config, ResumePoint(episode=cut + 1, tick=tick, replayed=last_row - cut,
                               lagging=lagging)


def rewind(out: Path, start: ResumePoint) -> None:
    """Drop the rows past the cut from ``episodes.csv``: they are played again."""
    if start.replayed:
        keep_rows(Path(out) / EPISODES_FILE, start.episode)


def shared_table(out: Path, config: SwarmConfig, start: ResumePoint) -> SharedState | None:
    """The shared state the world of a resumed run starts from (None where the agents learn
    apart, or nothing was learned yet, or nothing is left to play); raises ResumeError naming
    the file."""
    if not config.shared or not 0 < start.episode < config.episodes:
        return None
    try:
        return world_checkpoint.load(world_checkpoint.table_path(out), config, start.cut)
    except CheckpointError as error:
        raise ResumeError(str(error)) from None
