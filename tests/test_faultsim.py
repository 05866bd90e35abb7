"""The deterministic simulator and its fault schedules (sim/, launch/faultsim.py).

Ten thousand seeded schedules of 8 agents, each with its own faults, must pass every check of
``sim.checks`` (and equal ``--in-process`` where their faults are benign); each bug they found
on the way keeps its schedule here (its seed, and what that seed drew then); a run without
faults equals ``--in-process`` file for file; one seed reproduces one history exactly.
"""

import subprocess
import sys
import time
from collections import Counter
from dataclasses import replace

import msgspec
import numpy as np
import pytest

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.agent.agent_machine import AgentMachine
from nnql_swarm.launch import faultsim
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.sim.inprocess import run_in_process
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.protocol.messages import encode
from nnql_swarm.sim.schedule import FORGE, KINDS, Fault, Schedule, draw_schedule
from nnql_swarm.sim.parity import parity_failures
from nnql_swarm.sim.distributed import SimSwarm, run_schedule
from tests.swarm_helpers import ROOT
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes

SCHEDULES = 10_000

BUGS = {
    116: "a completed world sent one shutdown; it was lost on the way and an agent waited for "
         "ever for a world that had gone",
    508: "a world resumed under running agents replays tick numbers; answers still on their way "
         "from the world before counted for the new one, and relayed intents changed",
    2151: "a duplicated query replaced a standing one at its target, ending it while its asker "
          "waited for its answer; the asker waited out the time-out: decisions differed from "
          "--in-process",
    5382: "the world crashed while telling its agents the run was over; the world resumed after "
          "the last episode ended without telling them, and an agent waited for ever",
    9563: "the world stalled for longer than it meant to tell its agents to stop, and gave up "
          "without telling those a partition had cut off",
    176: "(the simulator) a query's end overtook its replies, which Zenoh keeps in order",
    1834: "(the simulator) a stalled process was resumed after it had stopped meanwhile",
    20794: "(the simulator) an agent was restarted after the world had said the run was over, "
           "then counted as never stopping",
}
"""What each schedule of :data:`FOUND` broke; each fails again with its fix undone."""



def PAPER_CONFIG(**values) -> SwarmConfig:  # noqa: N802 (reads as the SwarmConfig it makes)
    """A config with the paper's learning options, which these schedules run."""
    return SwarmConfig(**{**PRESETS["nnql"], **values})


FOUND = {  # the schedules written out whole, so that sim/schedule.py's draws cannot change them
    116: Schedule(
        116, PAPER_CONFIG(run_id='sim116', episodes=2, max_steps=8, width=11,
                       height=11, seed=116, count_swaps=False, tick_deadline_s=0.5),
        (0.00015437322974409877, 0.0008459641393827896), (
            Fault('drop', 17, 0.0035970798479958376, 1.6648105123555081, p=0.20192673621801357),
            Fault('duplicate', 7, 0.001220328501036098, 0.7235192242324396, p=0.43479034081134355),
            Fault('partition', 15, 0.001071595450186948, 0.5682154940375999,
                  group=frozenset(['agent-1', 'agent-2', 'agent-4', 'agent-7', 'world'])),
        )),
    508: Schedule(
        508, PAPER_CONFIG(run_id='sim508', episodes=2, max_steps=8, width=24,
                       height=24, seed=508, count_swaps=False, tick_deadline_s=0.5),
        (7.845590186761891e-05, 0.0006427328886513944), (
            Fault('partition', 8, 0.0030566456960463206, 0.08378666955775729,
                  group=frozenset(['agent-0', 'agent-2', 'agent-6', 'agent-7'])),
            Fault('crash', 15, 0.0010395566704450344, 1.7697390735979894, target='world'),
        )),
    2151: Schedule(
        2151, PAPER_CONFIG(run_id='sim2151', episodes=2, max_steps=4, width=11,
                       height=11, seed=2151, count_swaps=False, tick_deadline_s=0.5),
        (5.150060742515379e-05, 0.0001828805510616076), (
            Fault('duplicate', 0, 0.0006005370980102578, 1.0055399056883594, p=0.3688527012841665),
        )),
    5382: Schedule(
        5382, PAPER_CONFIG(run_id='sim5382', episodes=2, max_steps=5, width=30,
                       height=14, seed=5382, count_swaps=False, tick_deadline_s=0.5),
        (0.00014557847060894303, 0.000594406027418469), (
            Fault('stall', 3, 0.0009388533645840443, 1.8514796001970066, target='world'),
            Fault('drop', 11, 0.0005495144182472682, 1.5254922498387558, p=0.1377082094622803),
            Fault('duplicate', 3, 0.0021489299397489813, 0.3330695076448985, p=0.28964408388192536),
            Fault('crash', 11, 0.0020737492267926387, 2.506511067451298, target='world'),
        )),
    9563: Schedule(
        9563, PAPER_CONFIG(run_id='sim9563', episodes=2, max_steps=6, width=30,
                       height=14, seed=9563, count_swaps=False, tick_deadline_s=0.5),
        (2.489336807221189e-05, 0.0005116315620147735), (
            Fault('crash', 7, 0.00042524699951839476, 1.8717332126767234, target='agent-1'),
            Fault('partition', 12, 0.0026607206908393108, 0.22629872719983912,
                  group=frozenset(['agent-1', 'agent-2', 'agent-3', 'world'])),
            Fault('stall', 13, 0.003919791434692538, 2.930226303934185, target='world'),
        )),
    176: Schedule(
        176, PAPER_CONFIG(run_id='sim176', episodes=2, max_steps=6, width=30,
                       height=14, seed=176, count_swaps=False, tick_deadline_s=0.5),
        (0.00013679417266388124, 0.0005505395255952156), (
            Fault('reorder', 9, 0.0012586221509362093, 0.9534241957870209, p=0.29536697554322533),
        )),
    1834: Schedule(
        1834, PAPER_CONFIG(run_id='sim1834', episodes=2, max_steps=3, width=24,
                       height=24, seed=1834, count_swaps=True, tick_deadline_s=0.5),
        (0.0001751135654647304, 0.00018266964497069206), (
            Fault('reorder', 2, 0.002046471161092082, 1.8716246043063487, p=0.26077320046260377),
            Fault('stall', 6, 0.0014228254878294582, 0.5100850430092169, target='agent-1'),
        )),
    20794: Schedule(
        20794, PAPER_CONFIG(run_id='sim20794', episodes=2, max_steps=4, width=11,
                       height=11, seed=20794, count_swaps=True, tick_deadline_s=0.5),
        (2.620259174316997e-05, 0.0005605777902883565), (
            Fault('stall', 9, 0.001905405678799475, 2.948539624643046, target='world'),
            Fault('crash', 5, 0.0030330134373254746, 1.922162816026118, target='agent-0'),
            Fault('duplicate', 4, 0.0024348382365189294, 0.6338957616059013, p=0.4820613909988755),
            Fault('drop', 9, 0.0020345867270493184, 0.7046542017751871, p=0.2640276263237157),
        )),
}


@pytest.mark.parametrize("seed", sorted(FOUND))
def test_the_schedules_that_found_a_bug_pass(seed, tmp_path):
    schedule = FOUND[seed]
    outcome = run_schedule(schedule, tmp_path, fingerprints=schedule.benign)
    failures = outcome.failures
    if schedule.benign and not failures:
        failures = parity_failures(schedule.config, outcome.rows, outcome.fingerprints)
    assert failures == [], f"{BUGS[seed]}: {failures}"
    assert set(outcome.fired) == {fault.kind for fault in schedule.faults}, "every fault hit"


def test_a_workers_schedules_do_not_see_each_others_files(tmp_path):
    """(the simulator) Each schedule has a checkpoint directory of its own: an agent restarted in
    one schedule never loads another's from a worker's shared directory."""
    crashing = [seed for seed in range(200) if draw_schedule(seed).crashing_agents][:4]
    for name in [f"alone-{seed}" for seed in crashing] + ["shared"]:
        (tmp_path / name).mkdir()
    alone = [faultsim.check_schedule(seed, 8, tmp_path / f"alone-{seed}") for seed in crashing]
    together = [faultsim.check_schedule(seed, 8, tmp_path / "shared") for seed in crashing]
    assert together == alone and all(r.failures == () for r in together)
    assert list((tmp_path / "shared").iterdir()) == [], "each schedule cleans up after itself"


@pytest.mark.full
@pytest.mark.timeout(1200)  # 3.5 to 6.5 minutes beside the rest of the parallel pass
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
    assert all(fired[kind] >= SCHEDULES // 20 for kind in (*KINDS, FORGE)), fired
    assert sum(1 for r in results if not r.fired) >= SCHEDULES // 20, "some ran without faults"


@pytest.mark.parametrize("algo, grid, walls", [
    ("nnql", (11, 11), 0.0), ("nnql", (30, 14), 0.0), ("ql", (11, 11), 0.0),
    ("nnql-dir", (16, 16), 0.0), ("nnql", (14, 14), 0.25), ("daql", (14, 14), 0.25),
    ("ql", (24, 24), 0.2), ("path-nnql", (19, 19), 0.2), ("shield-nnql", (14, 14), 0.25),
    ("pibt-nnql", (9, 9), 0.0)])
def test_without_faults_the_simulator_gives_the_in_process_run_file_for_file(tmp_path, algo, grid,
                                                                             walls):
    learning = PRESETS[algo] if algo in PRESETS else dict(
        algo=algo, interaction_radius=10 if algo == "daql" else 2)
    config = SwarmConfig(run_id="parity", n_agents=8, episodes=4, max_steps=40, seed=3,
                         width=grid[0], height=grid[1], obstacle_density=walls, **learning)
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
        a = read_fields(agent_checkpoint.checkpoint_path(tmp_path / "sim" / "checkpoints",
                                                              agent), ())
        b = read_fields(agent_checkpoint.checkpoint_path(tmp_path / "local" / "checkpoints",
                                                              agent), ())
        assert np.array_equal(a["q_ds"], b["q_ds"]) and np.array_equal(a["q_ca"], b["q_ca"])
        assert np.array_equal(a["known_walls"], b["known_walls"])


def test_one_seed_gives_one_history():
    for seed in (3, 508, 777):
        first, again = run_schedule(draw_schedule(seed)), run_schedule(draw_schedule(seed))
        assert (first.digest, first.events, first.rows) == (again.digest, again.events, again.rows)
    assert draw_schedule(5) == draw_schedule(5) and draw_schedule(5) != draw_schedule(6)
    benign = replace(draw_schedule(3), faults=())
    assert run_schedule(benign).digest != run_schedule(draw_schedule(3)).digest


def test_a_broken_protocol_is_caught_and_reported_with_the_seed_that_reproduces_it(
        monkeypatch, capsys):
    decide = AgentMachine._decide

    def forgetful(self, obs, plan, answers):  # a bug: an agent relays a wrong intent now and then
        decide(self, obs, plan, answers)
        answer = self.decided_answer
        if answer.relayed and obs.tick % 3 == 2:
            (j, action), *rest = answer.relayed
            wrong = msgspec.structs.replace(answer, relayed=((j, (action + 1) % 5), *rest))
            self.decided_answer, self.decided_payload = wrong, encode(wrong)

    monkeypatch.setattr(AgentMachine, "_decide", forgetful)
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
