"""The deterministic simulator and its fault schedules (sim/, launch/faultsim.py).

Ten thousand seeded schedules of 8 agents, each with its own faults, must pass every check of
``sim.checks`` (and equal ``--in-process`` where their faults are benign); each bug they found
on the way keeps its seed here; a run without faults equals ``--in-process`` file for file; one
seed reproduces one history exactly.
"""

import subprocess
import sys
import time
from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from agent import checkpoint
from agent.protocol import AgentProtocol
from launch import faultsim
from launch.inprocess import run_in_process
from protocol.config import SwarmConfig
from protocol.messages import encode
from sim.schedule import KINDS, Schedule, draw_schedule
from sim.swarm import SimSwarm, run_schedule
from tests.swarm_helpers import ROOT
from world.engine import EPISODE_FIELDS
from world.metrics import read_episodes

SCHEDULES = 10_000

REGRESSIONS = {
    116: "a completed world's one shutdown was lost on the way: an agent waited for ever",
    508: "a world resumed under running agents replays tick numbers, and answers still on their "
         "way from the world before counted for the new one: relayed intents changed",
    2151: "a standing query ended (a duplicated query replaced it) while the agent waited for its "
          "answer, and the agent waited out the time-out instead of asking: decisions differed "
          "from --in-process",
    5382: "the world crashed while telling its agents the run was over, and a world resumed "
          "after the last episode exited without telling them: an agent waited for ever",
    9563: "the world stalled for longer than it meant to tell its agents to stop, and gave up "
          "without telling those a partition had cut off",
    9582: "a stalled world handled the last agents leaving and a restarted one coming up all at "
          "once, and ended before it saw the newcomer",
    176: "the simulator let a query's end overtake its replies (Zenoh keeps them in order)",
    1834: "the simulator resumed a stalled process that had stopped meanwhile",
    20794: "the simulator restarted an agent after the world had said the run was over",
}


@pytest.mark.parametrize("seed", sorted(REGRESSIONS))
def test_the_schedules_that_found_a_bug_pass(seed):
    result = faultsim.check_schedule(seed, 8)
    assert result.failures == (), f"{REGRESSIONS[seed]}: {result.failures}"


def test_ten_thousand_schedules_pass(capsys):
    started = time.monotonic()
    results = faultsim.run_schedules(SCHEDULES, seed_base=0, agents=8, workers=2)
    elapsed = time.monotonic() - started
    with capsys.disabled():
        print(f"\n{SCHEDULES} fault schedules in {elapsed:.1f} s on 2 workers")
    assert [r.seed for r in results] == list(range(SCHEDULES))
    failed = {r.seed: r.failures for r in results if r.failures}
    assert failed == {}
    fired = Counter(kind for r in results for kind in r.fired)
    assert all(fired[kind] >= SCHEDULES // 20 for kind in KINDS), fired
    assert sum(1 for r in results if not r.fired) >= SCHEDULES // 20, "some ran without faults"


@pytest.mark.parametrize("algo, grid", [("nnql", (11, 11)), ("nnql", (30, 14)), ("ql", (11, 11)),
                                        ("nnql-dir", (16, 16))])
def test_without_faults_the_simulator_gives_the_in_process_run_file_for_file(tmp_path, algo, grid):
    config = SwarmConfig(run_id="parity", n_agents=8, episodes=4, max_steps=40, seed=3,
                         algo=algo, width=grid[0], height=grid[1])
    schedule = Schedule(3, config, latency=(50e-6, 400e-6), faults=())
    (tmp_path / "sim").mkdir()
    outcome = SimSwarm(schedule, tmp_path / "sim", checkpoint_all=True, write_metrics=True).run()
    assert outcome.failures == []
    (tmp_path / "local").mkdir()
    run_in_process(config, tmp_path / "local")

    def deterministic(path):
        return [tuple(r[f] for f in EPISODE_FIELDS) for r in read_episodes(path / "episodes.csv")]

    assert deterministic(tmp_path / "sim") == deterministic(tmp_path / "local")
    assert sum(int(r[3]) for r in deterministic(tmp_path / "sim")) == 0, "no intent missed"
    for agent in range(8):
        a = np.load(checkpoint.checkpoint_path(tmp_path / "sim" / "checkpoints", agent))
        b = np.load(checkpoint.checkpoint_path(tmp_path / "local" / "checkpoints", agent))
        assert np.array_equal(a["q_ds"], b["q_ds"]) and np.array_equal(a["q_ca"], b["q_ca"])


def test_one_seed_gives_one_history():
    for seed in (3, 508, 777):
        first, again = run_schedule(draw_schedule(seed)), run_schedule(draw_schedule(seed))
        assert (first.digest, first.events, first.rows) == (again.digest, again.events, again.rows)
    assert draw_schedule(5) == draw_schedule(5) and draw_schedule(5) != draw_schedule(6)
    benign = replace(draw_schedule(3), faults=())
    assert run_schedule(benign).digest != run_schedule(draw_schedule(3)).digest


def test_a_broken_protocol_is_caught_and_reported_with_the_seed_that_reproduces_it(
        monkeypatch, capsys):
    decide = AgentProtocol._decide

    def forgetful(self, obs, answers):  # a bug: an agent relays a wrong intent now and then
        decide(self, obs, answers)
        answer = self.decided_answer
        if answer.relayed and obs.tick % 3 == 2:
            (j, action), *rest = answer.relayed
            wrong = answer._replace(relayed=((j, (action + 1) % 5), *rest))
            self.decided_answer, self.decided_payload = wrong, encode(wrong)

    monkeypatch.setattr(AgentProtocol, "_decide", forgetful)
    seed = next(s for s in range(200) if faultsim.check_schedule(s, 8).failures)
    first, again = faultsim.check_schedule(seed, 8), faultsim.check_schedule(seed, 8)
    assert first == again and "intent changed" in first.failures[0]
    assert faultsim.main(["--seed-base", str(seed), "--schedules", "1", "--workers", "1",
                          "--no-progress"]) == 1
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith(f"schedule {seed} FAILED (digest {first.digest}): ")
    assert f"reproduce: python launch/faultsim.py --seed-base {seed} --schedules 1" in out[-2]
    assert out[-1] == "1 schedules, 1 failures"


def test_the_command_line_ends_with_its_count_and_refuses_bad_flags_in_one_line():
    command = [sys.executable, str(ROOT / "launch" / "faultsim.py")]
    done = subprocess.run([*command, "--schedules", "30", "--seed-base", "40", "--no-progress"],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.splitlines()[-1] == "30 schedules, 0 failures"
    for flags, message in [(["--schedules", "0"], "--schedules must be at least 1"),
                           (["--seed-base", "-1"], "--seed-base must be 0 .. 2**63 - 1"),
                           (["--seed-base", str(2**63)], "--seed-base must be 0 .. 2**63 - 1"),
                           (["--agents", "0"], "--agents must be"),
                           (["--workers", "0"], "--workers must be"),
                           (["--schedules", "many"], "invalid int value")]:
        bad = subprocess.run([*command, *flags], capture_output=True, text=True, timeout=60)
        lines = bad.stderr.strip().splitlines()
        assert bad.returncode == 2 and len(lines) == 1 and message in lines[0], bad.stderr
