"""Q-table checkpoints of one agent, rewritten in place at every episode's end (``transport.slotfile``:
a reader sees the old checkpoint or the new, whatever is killed when).

A checkpoint holds both tables, the exploration counter, the agent's generator state, the walls
it has seen (``learning.known_map``) and the episode it completes, plus what it belongs to (agent id, agent count, algorithm, and
the run's identity, ``SwarmConfig.identity``), so a checkpoint from another run, of another shape
or not, is refused with a clear error naming the file.
"""

import hashlib
import json
from pathlib import Path
from typing import Protocol

import numpy as np

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.learning.saved import CheckpointError, check_run, check_tables, read_versions
from nnql_swarm.transport import slotfile
from nnql_swarm.protocol.config import SwarmConfig


class SavedTables(Protocol):
    """What a checkpoint reads of a learner (``learning.tables.Learner``, or the simulator's
    view of one)."""

    @property
    def actions_taken(self) -> int: ...

    def tables(self) -> tuple[np.ndarray, np.ndarray]: ...

    def known_walls(self) -> list[int]: ...


class Saved(Protocol):
    """What a checkpoint saves of an agent: an ``agent.brain.AgentBrain``, or the simulator's
    view of one (``sim.inprocess.SimulatedAgent``)."""

    @property
    def agent(self) -> int: ...

    @property
    def config(self) -> SwarmConfig: ...

    @property
    def learner(self) -> SavedTables: ...

    @property
    def rng(self) -> np.random.Generator: ...


def fingerprint(brain: Saved) -> str:
    """A short digest of the brain's Q-tables: equal digests, equal learned values."""
    q_ds, q_ca = brain.learner.tables()
    digest = hashlib.sha256(q_ds.tobytes())
    digest.update(q_ca.tobytes())
    return digest.hexdigest()[:16]


def checkpoint_path(directory: Path, agent: int) -> Path:
    return Path(directory) / f"agent-{agent}.ckpt"


def save(path: "Path | slotfile.SlotFile", brain: Saved, episode: int) -> None:
    """Write the brain's learned state after ``episode``; readers see the old file or the new."""
    q_ds, q_ca = brain.learner.tables()
    slotfile.write(path, {"q_ds": q_ds, "q_ca": q_ca,
                          "actions_taken": int(brain.learner.actions_taken), "episode": episode,
                          "agent": brain.agent, "n_agents": brain.config.n_agents,
                          "algo": brain.config.algo, "run": brain.config.identity,
                          "rng_state": json.dumps(brain.rng.bit_generator.state),
                          "known_walls": np.array(brain.learner.known_walls(), dtype=np.int64)})


FIELDS = ("q_ds", "q_ca", "actions_taken", "episode", "agent", "n_agents", "algo", "rng_state")


def episodes(path: Path) -> list[int]:
    """The episodes whose state the file holds, the newest first (``transport.slotfile`` keeps
    two); raises CheckpointError naming the file."""
    return [int(fields["episode"]) for fields in read_versions(path, FIELDS)]


def load(path: Path, brain: AgentBrain, episode: int | None = None) -> int:
    """Restore the brain from a checkpoint, its newest version or the one of ``episode``;
    returns the episode it completes."""
    path = Path(path)
    versions = read_versions(path, FIELDS)
    fields = versions[0] if episode is None else \
        next((v for v in versions if int(v["episode"]) == episode), None)
    if fields is None:
        held = sorted(int(v["episode"]) for v in versions)
        raise CheckpointError(f"{path}: holds episodes {held}, not episode {episode}")
    check_tables(path, fields, brain.learner.tables())
    owner = (int(fields["agent"]), int(fields["n_agents"]), str(fields["algo"]))
    mine = (brain.agent, brain.config.n_agents, brain.config.algo)
    if owner != mine:
        raise CheckpointError(
            f"{path}: belongs to agent {owner[0]} of {owner[1]} ({owner[2]}), "
            f"not agent {mine[0]} of {mine[1]} ({mine[2]})"
        )
    check_run(path, fields, brain.config)
    try:  # a checkpoint without ``known_walls`` knows no wall
        brain.learner.restore(fields["q_ds"], fields["q_ca"], int(fields["actions_taken"]),
                              np.asarray(fields.get("known_walls", ())).reshape(-1).tolist())
    except ValueError as error:
        raise CheckpointError(f"{path}: {error}") from None
    try:
        brain.rng.bit_generator.state = json.loads(str(fields["rng_state"]))
    except (ValueError, TypeError, KeyError) as error:
        raise CheckpointError(f"{path}: bad generator state ({error})") from None
    return int(fields["episode"])
