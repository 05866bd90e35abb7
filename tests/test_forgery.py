"""A compromised agent on the secured layout (``docs/operations.md``): authenticated as itself, it
plays honestly but forges its learning records from a given tick on (``tests/forging_agent.py``:
collisions pay). The world refuses them (``world.records``) and counts them, the run completes,
and the shared table, every honest agent's copy with it, is the very one of the same run in
which that agent sent no record from that tick on: nothing the forger said was believed, and
every honest agent's record was."""

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import stats_path
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import ROOT, SWARM
from tests.test_security import AGENTS, make_secured

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

FORGER = AGENTS - 1
FROM_TICK = 12
EPISODES = 3


@pytest.fixture(scope="module")
def router(tmp_path_factory):
    secured = make_secured(tmp_path_factory.mktemp("forgery"), "mtls+password")
    yield secured
    secured.stop()


def run(out, secured, run_id: str, *forger_flags: str) -> dict[str, subprocess.Popen]:
    """A secured run: the world, agents 0 to 6 and the forger, each its own process tree; waits
    until all have exited."""
    options = ["--run-id", run_id, "--agents", str(AGENTS), "--episodes", str(EPISODES),
               "--max-steps", "30", "--seed", "4", "--deadline", "10", "--no-record",
               "--no-progress", "--out", str(out), "--zenoh-config-dir", str(secured.dir)]
    commands = {
        "world": [sys.executable, str(SWARM), "--role", "world", *options],
        "agents": [sys.executable, str(SWARM), "--role", "agents", "--agent-ids",
                   f"0-{FORGER - 1}", *options],
        "forger": [sys.executable, str(ROOT / "tests" / "forging_agent.py"), "--from-tick",
                   str(FROM_TICK), *forger_flags, "--role", "agents", "--agent-ids", str(FORGER),
                   *options],
    }
    logs = out.parent / f"{run_id}-logs"
    logs.mkdir(parents=True, exist_ok=True)
    processes = {}
    try:
        for name, command in commands.items():
            with open(logs / f"{name}.log", "w") as log:
                processes[name] = subprocess.Popen(command, cwd=ROOT, stdout=log, stderr=log,
                                                   start_new_session=True)
        for process in processes.values():
            process.wait(timeout=300)
    finally:
        for process in processes.values():
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
    for name, process in processes.items():
        assert process.returncode == 0, (name, (logs / f"{name}.log").read_text()[-3000:])
    return processes


def tables(out):
    """The run's shared table at its end, read as its own run's (each run has its identity)."""
    config = SwarmConfig.from_json((out / "config.json").read_text())
    return world_checkpoint.load(world_checkpoint.table_path(out), config, EPISODES - 1)


def deterministic(out) -> list[tuple]:
    return [tuple(row[f] for f in EPISODE_FIELDS) for row in read_episodes(out / "episodes.csv")]


def test_a_forging_agents_records_are_refused_and_the_honest_agents_table_is_unchanged(
        router, tmp_path):
    mute, forging = tmp_path / "mute", tmp_path / "forging"
    run(mute, router, "mute", "--mute")
    run(forging, router, "forging")
    config = SwarmConfig.from_json((forging / "config.json").read_text())
    assert config.shared, "the default preset shares one table"

    world = json.loads(stats_path(forging, "world").read_text())
    assert world["completed"] and world["forgers"] == [FORGER]
    refused = world["rejected"]
    assert refused.get("forged-record") == 1 and refused.get("barred-record", 0) > 0, refused
    assert set(refused) == {"forged-record", "barred-record"}, refused
    quiet = json.loads(stats_path(mute, "world").read_text())
    assert quiet["completed"] and quiet["rejected"] == {} and quiet["forgers"] == []

    assert [int(r["episode"]) for r in read_episodes(forging / "episodes.csv")] == [0, 1, 2]
    assert all(int(r["missed_intents"]) == 0 for r in read_episodes(forging / "episodes.csv"))
    assert deterministic(forging) == deterministic(mute), "the forger's intents still count"
    shared, reference = tables(forging), tables(mute)
    assert np.array_equal(shared[0], reference[0]) and np.array_equal(shared[1], reference[1])
    for agent in range(FORGER):
        saved = agent_checkpoint.checkpoint_path(forging / "checkpoints", agent)
        mine = read_fields(saved, ())
        assert np.array_equal(mine["q_ds"], shared[0]) and np.array_equal(mine["q_ca"], shared[1])
