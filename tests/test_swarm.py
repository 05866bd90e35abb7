"""The distributed swarm end to end: real processes, real Zenoh sessions on loopback, real Rerun files."""

import csv
import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.learning import ahead
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.world import world_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import stats_path
from tests.swarm_helpers import SWARM, group_pids, run_swarm, start_swarm, stops_within
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import COLUMNS, read_episodes

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

RUN = ("--agents", "8", "--episodes", "4", "--max-steps", "40", "--seed", "3")


def deterministic(rows: list[dict]) -> list[tuple]:
    return [tuple(row[f] for f in EPISODE_FIELDS) for row in rows]


@pytest.fixture(scope="module")
def distributed_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("swarm") / "run"
    result = run_swarm(out, *RUN, "--run-id", "dist")
    return out, result


def test_distributed_run_completes_and_writes_everything(distributed_run):
    out, result = distributed_run
    assert result.returncode == 0, result.stderr
    rows = read_episodes(out / "episodes.csv")
    assert list(rows[0]) == list(COLUMNS)
    assert [int(r["episode"]) for r in rows] == [0, 1, 2, 3]
    for row in rows:
        assert 1 <= int(row["steps"]) <= 40
        assert int(row["missed_intents"]) == 0
        assert 0 <= int(row["arrived"]) <= 8
    config = SwarmConfig.from_json((out / "config.json").read_text())
    assert config.n_agents == 8 and config.run_id == "dist"
    assert "invariants" not in result.stderr


def test_no_process_refuses_a_message_another_made(distributed_run):
    """Senders do not parse what they encode: every payload is judged where it arrives, and in a
    run without faults or forgeries nothing a node made may be refused there."""
    out, _ = distributed_run
    for name in ("world", *(f"agent-{i}" for i in range(8))):
        stats = json.loads(stats_path(out, name).read_text())
        assert stats["rejected"] == {} and stats["accepted"] > 0, (name, stats)


def test_every_process_counts_what_each_input_cost_it(distributed_run):
    """The stats carry each input's calls and its CPU time a call, in the machine and in its
    effects (``transport.adapter``): every agent decided on observations, and the world heard
    an intent from each agent at each tick it decided."""
    out, _ = distributed_run
    rows = read_episodes(out / "episodes.csv")
    world = json.loads(stats_path(out, "world").read_text())["handler_cpu"]
    assert world["on_intent"]["calls"] >= sum(int(r["agent_steps"]) for r in rows) > 0
    assert world["on_intent"]["machine_us"] > 0
    for agent in range(8):
        costs = json.loads(stats_path(out, f"agent-{agent}").read_text())["handler_cpu"]
        observed = costs["on_observation"]
        assert observed["calls"] >= len(rows), (agent, costs)
        assert observed["machine_us"] > 0 and observed["effects_us"] > 0, (agent, costs)
        assert {"calls", "machine_us", "effects_us"} == set(costs["on_liveliness"])


def test_every_agent_decided_by_its_decision_compiled_ahead_of_time(distributed_run):
    """The launcher builds the agents' decision ahead of time where it is missing
    (``learning.ahead``), and every agent process, which runs no numba, decides with it."""
    out, _ = distributed_run
    for agent in range(8):
        stats = json.loads(stats_path(out, f"agent-{agent}").read_text())
        assert stats["decides"] == ahead.AHEAD, (agent, stats)


def test_recording_verifies(distributed_run):
    out, _ = distributed_run
    rerun = os.path.join(os.path.dirname(sys.executable), "rerun")
    verify = subprocess.run([rerun, "rrd", "verify", str(out / "run.rrd")],
                            capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def test_every_agent_checkpointed_its_last_episode(distributed_run):
    out, _ = distributed_run
    config = SwarmConfig.from_json((out / "config.json").read_text())
    for agent in range(config.n_agents):
        brain = AgentBrain(agent, config)
        episode = agent_checkpoint.load(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), brain)
        assert episode == config.episodes - 1
        assert np.abs(brain.learner.q_ds).sum() > 0
    assert config.shared
    shared = world_checkpoint.load(world_checkpoint.table_path(out), config, config.episodes - 1)
    assert all(np.array_equal(a, b) for a, b in zip(shared, brain.learner.tables())), \
        "the world's copy of the shared table equals every agent's"


def test_in_process_and_distributed_runs_are_identical(distributed_run, tmp_path):
    out, result = distributed_run
    assert result.returncode == 0, result.stderr
    local = tmp_path / "local"
    in_process = run_swarm(local, *RUN, "--run-id", "dist", "--in-process")
    assert in_process.returncode == 0, in_process.stderr
    assert deterministic(read_episodes(local / "episodes.csv")) == deterministic(
        read_episodes(out / "episodes.csv"))
    for agent in range(8):
        a = read_fields(agent_checkpoint.checkpoint_path(local / "checkpoints", agent), ())
        b = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), ())
        assert np.array_equal(a["q_ds"], b["q_ds"]) and np.array_equal(a["q_ca"], b["q_ca"])
        assert np.array_equal(a["known_walls"], b["known_walls"])


def test_ql_swarm_runs_distributed(tmp_path):
    result = run_swarm(tmp_path / "ql", "--agents", "4", "--episodes", "2", "--max-steps", "20",
                       "--algo", "ql", "--no-record")
    assert result.returncode == 0, result.stderr
    assert len(read_episodes(tmp_path / "ql" / "episodes.csv")) == 2
    assert not (tmp_path / "ql" / "run.rrd").exists()


@pytest.mark.parametrize("options, message", [
    (("--agents", "0"), "agents must be"),
    (("--agents", "80"), "distinct start and goal cells"),
    (("--grid", "11by11"), "WIDTHxHEIGHT"),
    (("--algo", "dqn"), "algo must be one of"),
    (("--wait-rule", "near"), "the wait rule must be one of"),
    (("--goal-reward", "nan"), "the goal reward must be"),
    (("--episodes", "-1"), "episodes must be"),
    (("--role", "world"), "needs --listen"),
    (("--zenoh-config", "/nonexistent.json5"), "no Zenoh config file"),
    (("--run-id", "bad id!"), "invalid run id"),
    (("--topology", "hub-peer", "--connect", "tcp/127.0.0.1:7447"), "--topology lays out"),
    (("--topology", "ring"), "invalid choice"),
])
def test_bad_options_give_one_line_and_exit_2(tmp_path, options, message):
    result = run_swarm(tmp_path / "bad", *options, timeout=60)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip() and "usage:" not in line]
    assert len(lines) == 1 and message in lines[0], result.stderr
    assert "Traceback" not in result.stderr


def test_an_existing_run_is_never_overwritten(distributed_run):
    out, _ = distributed_run
    before = (out / "episodes.csv").read_bytes()
    result = run_swarm(out, *RUN, timeout=60)
    assert result.returncode == 2 and "already holds a run" in result.stderr
    assert (out / "episodes.csv").read_bytes() == before


@pytest.mark.serial  # within 3 s
def test_ctrl_c_stops_every_process_within_3_s(tmp_path):
    out = tmp_path / "interrupted"
    swarm = start_swarm(out, "--agents", "8", "--episodes", "1000")
    try:
        deadline = time.monotonic() + 90
        while time.monotonic() < deadline:
            if (out / "episodes.csv").exists() and len(read_episodes(out / "episodes.csv")) >= 1:
                break
            time.sleep(0.2)
        else:
            pytest.fail("the swarm did not finish an episode in time")
        assert len(group_pids(swarm.pid)) >= 10  # launcher, world, 8 agents (+ resource tracker)
        os.killpg(swarm.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
        assert stops_within(swarm, 3) < 3
        assert group_pids(swarm.pid) == []
        assert swarm.returncode == 130
        assert "Traceback" not in swarm.stderr_text()
        resume = next(line for line in swarm.stderr_text().splitlines() if "continue it" in line)
        assert "python" in resume and resume.endswith(f" {SWARM} --resume --out {out}")
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    rows = read_episodes(out / "episodes.csv")
    assert [int(r["episode"]) for r in rows] == list(range(len(rows)))
    with open(out / "episodes.csv", newline="") as f:
        assert all(len(row) == len(COLUMNS) for row in csv.reader(f))
    config = SwarmConfig.from_json((out / "config.json").read_text())
    for agent in range(8):
        agent_checkpoint.load(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), AgentBrain(agent, config))


@pytest.mark.parametrize("preset, topology, grid", [
    ("nnql", "auto", ()), ("best-nnql", "auto", ()), ("shield-nnql", "hub-peer", ()),
    ("shield-nnql", "auto", ("--grid", "14x12", "--obstacle-density", "0.25")),
    ("path-nnql", "auto", ("--grid", "14x12", "--obstacle-density", "0.25")),
    ("path-nnql", "auto", ("--grid", "14x12", "--obstacle-density", "0.25", "--still-shield",
                            "--agents", "10")),
    ("best-nnql", "auto", ("--wait-rule", "meet")),
    ("path-nnql", "auto", ("--grid", "14x12", "--obstacle-density", "0.25", "--on-target",
                            "step-aside", "--agents", "10")),
    ("best-nnql", "auto", ("--wait-rule", "meet", "--on-target", "step-aside")),
    ("pibt-nnql", "auto", ("--grid", "14x12", "--obstacle-density", "0.25", "--agents", "12")),
    ("pibt-nnql", "hub-peer", ("--map", "maze:15x15:4", "--agents", "10")),
    ("pibt-nnql", "auto", ("--map", "random:16x16:0.2:3", "--tasks", "lifelong", "--agents", "8")),
    ("path-nnql", "auto", ("--grid", "12x12", "--obstacle-density", "0.15", "--tasks",
                            "lifelong"))])
def test_each_preset_plays_the_same_run_distributed_and_in_process(preset, topology, grid,
                                                                   tmp_path):
    """The paper's reading (each agent its own tables) and the best options (one table shared
    over Zenoh, the direction-aware reading), the default with every agent a client of the
    world (the layout of 32 agents and more), a grid with walls, the default (``path-nnql``:
    destination seeking on the walls each agent has seen, the escape shield) there, and the direction-aware
    reading under the ``meet`` rule (a parked neighbour known to stay without an answer), the
    default with the still shield (neighbours' cells a tick ago), and the ``step-aside``
    on-target rule under both wait rules (arrived agents negotiate and make way), and priority
    inheritance over the agents' announced orders (``pibt-nnql``) among walls and in a maze, and
    lifelong runs (a new goal on every arrival) under both arbitrations: the same episodes,
    tables and known walls either way."""
    options = ("--agents", "6", "--episodes", "4", "--max-steps", "30", "--seed", "2",
               "--preset", preset, "--no-record", "--run-id", preset, *grid)
    distributed = run_swarm(tmp_path / "dist", *options, "--topology", topology)
    local = run_swarm(tmp_path / "local", *options, "--in-process")
    assert distributed.returncode == 0 and local.returncode == 0, distributed.stderr
    assert deterministic(read_episodes(tmp_path / "dist" / "episodes.csv")) == deterministic(
        read_episodes(tmp_path / "local" / "episodes.csv"))
    tables = [read_fields(agent_checkpoint.checkpoint_path(tmp_path / side / "checkpoints", 0),
                                     ()) for side in ("dist", "local")]
    assert np.array_equal(tables[0]["q_ca"], tables[1]["q_ca"])
    assert np.array_equal(tables[0]["q_ds"], tables[1]["q_ds"])
    assert np.array_equal(tables[0]["known_walls"], tables[1]["known_walls"])
    if grid and preset == "path-nnql":
        assert len(tables[0]["known_walls"]) > 0, "the walls it saw"
