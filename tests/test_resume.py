"""A resumed run is the run left alone: the cut over every process's files, and real runs
stopped at seeded moments in every way and resumed (``tests/interruptions.py``)."""

import re

import pytest

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.sim.resume import ResumeError, resume_point, rewind
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.metrics import EpisodeWriter, read_episodes
from nnql_swarm.world.shared_table import SharedState, SharedTable
from tests.interruptions import STOPS, draw_trials, run_left_alone, run_trials
from tests.swarm_helpers import run_swarm

N = 4


def lay_out_run(out, rows: int, agents: list[list[int]], world: list[int]) -> SwarmConfig:
    """A run directory with ``rows`` rows, agent ``i``'s checkpoint holding the episodes
    ``agents[i]`` (written in that order) and the world's holding ``world``."""
    config = SwarmConfig(n_agents=N, run_id="cut")
    (out / "config.json").write_text(config.to_json())
    with EpisodeWriter(out / "episodes.csv", sync=False) as writer:
        for e in range(rows):
            writer.write({"episode": e, "steps": 3, "collisions": 0, "missed_intents": 0,
                          "reward_sum": 1.0, "arrived": N, "shortest_sum": 4,
                          "agent_steps": 4, "end_tick": 4 * e + 3}, 0.1, 4)
    for agent, episodes in enumerate(agents):
        for e in episodes:
            brain = AgentBrain(agent, config)
            brain.learner.q_ds[0, 0] = float(e)
            agent_checkpoint.save(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), brain, e)
    for e in world:
        q_ds, q_ca = SharedTable(config).tables()
        world_checkpoint.save(world_checkpoint.table_path(out), SharedState(q_ds, q_ca), e, config)
    return config


def test_the_cut_is_the_last_episode_every_process_saved_and_later_rows_are_played_again(tmp_path):
    """A Ctrl-C that reached two agents after their end tick's checkpoint and the others before
    it: the world wrote the row of episode 45 of its table; agents 0 and 1 stand at 45, 2 and 3
    at 44. Everyone resumes after 44, each from that version of its file."""
    lay_out_run(tmp_path, 46, [[44, 45], [44, 45], [43, 44], [43, 44]], [44, 45])
    config, start = resume_point(tmp_path, list(range(N)), world=True)
    assert (start.episode, start.tick, start.replayed) == (45, 4 * 44 + 4, 1)
    rewind(tmp_path, start)
    assert [int(r["episode"]) for r in read_episodes(tmp_path / "episodes.csv")] == list(range(45))
    brain = AgentBrain(0, config)
    assert agent_checkpoint.load(agent_checkpoint.checkpoint_path(tmp_path / "checkpoints", 0), brain,
                           start.cut) == 44
    assert brain.learner.q_ds[0, 0] == 44.0


def test_a_run_stopped_before_any_process_saved_an_episode_starts_afresh(tmp_path):
    lay_out_run(tmp_path, 0, [[0], [], [], [0]], [])
    _, start = resume_point(tmp_path, list(range(N)), world=True)
    assert (start.episode, start.tick, start.replayed) == (0, 0, 0)


@pytest.mark.parametrize("agents, world", [
    ([[9, 10]] * 3 + [[]], [9, 10]),  # an agent's file lost
    ([[9, 10]] * 4, []),  # the world's
])
def test_a_process_without_checkpoint_stands_before_episode_0_and_the_run_starts_afresh(
        tmp_path, agents, world):
    lay_out_run(tmp_path, 11, agents, world)
    _, start = resume_point(tmp_path, list(range(N)), world=True)
    assert (start.episode, start.tick, start.replayed, start.exact) == (0, 0, 11, True)


def test_an_agent_two_episodes_behind_leaves_no_cut_and_everyone_goes_on_from_its_newest(
        tmp_path):
    """An agent that missed the ends of episodes 9 and 10 (partitioned, say): the others' files
    no longer hold its last episode, 8. The run goes on after its last row, each process from its
    newest checkpoint, and the files that cannot reach episode 8 are named."""
    lay_out_run(tmp_path, 11, [[9, 10]] * 3 + [[7, 8]], [9, 10])
    _, start = resume_point(tmp_path, list(range(N)), world=True)
    assert (start.episode, start.replayed, start.exact, start.checkpoint_episode) == \
        (11, 0, False, None)
    assert len(start.lagging) == 4 and "agent-0.ckpt holds episodes [9, 10], not 8" in \
        start.lagging[0]


def test_a_corrupt_checkpoint_is_refused_naming_the_file(tmp_path):
    lay_out_run(tmp_path, 11, [[9, 10]] * 4, [9, 10])
    (tmp_path / "checkpoints" / "agent-2.ckpt").write_bytes(b"garbage")
    with pytest.raises(ResumeError, match=re.escape("agent-2.ckpt: not a readable checkpoint")):
        resume_point(tmp_path, list(range(N)), world=True)


@pytest.mark.parametrize("file", ["agent-2.ckpt", "world.ckpt"])
def test_a_checkpoint_of_another_run_of_the_same_shape_is_refused_naming_the_file(tmp_path,
                                                                                  file):
    """Another seed, the same agents and tables: only the run's identity tells them apart."""
    ours, theirs = tmp_path / "ours", tmp_path / "theirs"
    ours.mkdir(), theirs.mkdir()
    config = lay_out_run(ours, 11, [[9, 10]] * N, [9, 10])
    other = SwarmConfig(n_agents=N, run_id="cut", seed=7)
    assert other.identity != config.identity
    brain = AgentBrain(2, other)
    agent_checkpoint.save(agent_checkpoint.checkpoint_path(theirs, 2), brain, 10)
    q_ds, q_ca = SharedTable(other).tables()
    world_checkpoint.save(theirs / "world.ckpt", SharedState(q_ds, q_ca), 10, other)
    (ours / "checkpoints" / file).write_bytes((theirs / file).read_bytes())
    with pytest.raises(ResumeError, match=re.escape(
            f"{file}: belongs to another run (identity {other.identity}), not this one "
            f"({config.identity})")):
        resume_point(ours, list(range(N)), world=True)


def test_a_config_json_edited_after_the_run_began_is_refused(tmp_path):
    lay_out_run(tmp_path, 3, [[2]] * N, [2])
    text = (tmp_path / "config.json").read_text()
    (tmp_path / "config.json").write_text(text.replace('"seed": 0', '"seed": 3'))
    with pytest.raises(ResumeError, match="edited after the run began"):
        resume_point(tmp_path, list(range(N)), world=True)


def test_a_run_written_by_another_version_is_refused_in_one_line(tmp_path):
    """Rows with other columns than this version's would be appended under the wrong header."""
    lay_out_run(tmp_path, 3, [[2]] * N, [2])
    episodes = tmp_path / "episodes.csv"
    header, _, rows = episodes.read_text().partition("\n")
    episodes.write_text(header.replace(",csr,isr,soc,makespan", "") + "\n" + rows)
    with pytest.raises(ResumeError, match="episodes.csv: its columns are not this version's"):
        resume_point(tmp_path, list(range(N)), world=True)


def test_resume_with_options_other_than_the_runs_says_so_in_one_line(tmp_path):
    out = tmp_path / "run"
    done = run_swarm(out, "--agents", "3", "--episodes", "2", "--max-steps", "10",
                     "--in-process", "--no-record")
    assert done.returncode == 0, done.stderr
    other = run_swarm(out, "--resume", "--episodes", "5", "--seed", "2", timeout=60)
    assert other.returncode == 2
    [line] = other.stderr.strip().splitlines()
    assert "config.json" in line and "episodes 5 (the run's: 2)" in line and \
        "seed 2 (the run's: 0)" in line
    same = run_swarm(out, "--resume", "--episodes", "2", "--agents", "3", timeout=60)
    assert same.returncode == 0 and "already complete" in same.stderr


def test_the_moments_are_spread_over_the_run_and_every_way_of_stopping_is_drawn():
    trials = draw_trials(7, 10, 100)
    assert [t.rows // 10 for t in trials] == list(range(10))
    assert sorted(t.stop for t in trials[:5]) == sorted(STOPS)
    assert draw_trials(7, 10, 100) == trials


@pytest.mark.parametrize("preset, grid", [
    ("shield-nnql", ()), ("best-nnql", ()),
    ("path-nnql", ("--grid", "24x12", "--obstacle-density", "0.2")),
    ("pibt-nnql", ("--grid", "16x16", "--obstacle-density", "0.2", "--tasks", "lifelong",
                   "--max-steps", "40"))])
@pytest.mark.full
def test_a_run_stopped_in_every_way_and_resumed_is_the_run_left_alone(tmp_path, preset, grid):
    """Five seeded moments over a short run, each stopped another way (``STOPS``) and resumed:
    the same rows and the same Q-tables, generators and shared table as the run left alone (the
    default among walls: the walls each agent has seen come back from its checkpoint; priority
    inheritance in a lifelong run: every agent's goals of an episode drawn again as they were)."""
    # A deadline no load reaches: an intent missed on a busy machine (the default's 2 s) changes
    # the rows of the run it falls in, left alone or resumed, and is not what is tested here.
    options = ["--preset", preset, "--episodes", "10", "--no-record", "--deadline", "30", *grid]
    expected = tmp_path / "left-alone"
    episodes = run_left_alone(expected, [*options, "--run-id", "left-alone", "--no-progress"])
    lines: list[str] = []
    outcomes = run_trials(tmp_path, options, draw_trials(11, 5, episodes), expected, lines.append)
    assert all(o.difference is None for o in outcomes), "\n".join(lines)
    assert sum(bool(o.resumed_at) for o in outcomes) >= 2, "runs were stopped after episodes"


def test_the_command_refuses_a_foreign_checkpoint_of_the_same_shape_in_one_line(tmp_path):
    options = ("--agents", "3", "--episodes", "4", "--max-steps", "10", "--in-process",
               "--no-record", "--run-id", "same")
    for name, seed in (("ours", "1"), ("theirs", "2")):
        done = run_swarm(tmp_path / name, *options, "--seed", seed)
        assert done.returncode == 0, done.stderr
    ours = tmp_path / "ours"
    rows = (ours / "episodes.csv").read_text()
    (ours / "episodes.csv").write_text("".join(rows.splitlines(keepends=True)[:3]))
    foreign = tmp_path / "theirs" / "checkpoints" / "agent-1.ckpt"
    (ours / "checkpoints" / "agent-1.ckpt").write_bytes(foreign.read_bytes())
    refused = run_swarm(ours, "--resume", timeout=60)
    assert refused.returncode == 2, refused.stderr
    [line] = refused.stderr.strip().splitlines()
    assert "agent-1.ckpt: belongs to another run" in line
    assert (ours / "episodes.csv").read_text() == "".join(rows.splitlines(keepends=True)[:3])
