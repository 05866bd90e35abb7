"""What an agent process starts from: a fresh brain, or the one its last checkpoint holds.

The agent node and the simulator's restarted agents both start here, so that a restart in the
simulator is the restart a real process makes.
"""

from pathlib import Path

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.config import SwarmConfig


def start_brain(agent: int, config: SwarmConfig, checkpoint_file: Path, resume: bool,
                brain: AgentBrain | None = None,
                episode: int | None = None) -> tuple[AgentBrain, dict | None]:
    """``(brain, resumed)``: ``brain`` (a fresh one if None), restored from ``checkpoint_file``
    when ``resume`` and the file exists, its newest version or, for a resumed run, the one of
    ``episode`` (the run's cut, ``sim.resume``); ``resumed`` then says from which
    episode and with which tables (``agent_checkpoint.fingerprint``), else None. Raises
    ``CheckpointError``."""
    brain = brain or AgentBrain(agent, config)
    if not (resume and Path(checkpoint_file).exists()):
        return brain, None
    episode = agent_checkpoint.load(checkpoint_file, brain, episode)
    return brain, {"episode": episode, "fingerprint": agent_checkpoint.fingerprint(brain)}
