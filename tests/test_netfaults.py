"""Faults on the real network between hosts: a swarm through a router across namespace hosts.

Each test runs tests/netfault_runs.py's layout (the router and the world on host ``world``, agents
0-1 on host ``a``, 2-3 on host ``b``) with one fault: netem's delay, jitter, reordering and loss
on the agents' hosts; the same delay, jitter and reordering in user space (for kernels without
netem); random loss by iptables; host a cut off for half a tick deadline and for
two and a half; the router killed and started again mid-run. Every run must complete: the
world and both agent launchers exit 0, every episode is written once and in order, the world's
invariants hold (``stats/world.json``: no violation), and no learned value is lost (every agent's
last checkpoint equals the world's copy of the shared table). The rows before the first episode
in which an intent was missed, or an agent decided without an intent it needed (its negotiation
timed out: ``decided_short`` in its stats), equal ``--in-process``'s; where neither happened,
every row does, and so does the shared table.

A partition that outlasts both Zenoh's lease and the run is not among them: it leaves the cut-off
host's launcher waiting (docs/operations.md; ``bench/netfaults.py --faults
partition-outlasting`` shows it).

A fault that the machine cannot make is skipped with the reason (pytest's ``-ra`` summary): the
namespaces need root and ``ip netns``, netem needs the kernel's ``sch_netem``, loss needs
``iptables`` with its ``statistic`` match (``make netfaults-tools`` installs the command).
"""

import json
from pathlib import Path

import numpy as np
import pytest

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import stats_path
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes
from tests import netfault_runs as runs
from tests import netns
from tests.swarm_helpers import run_swarm

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

AGENTS, EPISODES, MAX_STEPS, SEED = 4, 10, 30, 3
REASON = netns.unavailable_reason()


@pytest.fixture(scope="module")
def lan():
    if REASON is not None:
        pytest.skip(f"no network namespaces: {REASON}")
    with netns.Lan(runs.HOSTS) as lan:
        yield lan


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The same run ``--in-process``: its rows and its shared table."""
    if REASON is not None:
        pytest.skip(f"no network namespaces: {REASON}")
    out = tmp_path_factory.mktemp("in-process")
    result = run_swarm(out, "--agents", str(AGENTS), "--episodes", str(EPISODES), "--max-steps",
                       str(MAX_STEPS), "--seed", str(SEED), "--in-process", "--no-record",
                       timeout=180)
    assert result.returncode == 0, result.stderr
    rows = [tuple(r[f] for f in EPISODE_FIELDS) for r in read_episodes(out / "episodes.csv")]
    config = SwarmConfig.from_json((out / "config.json").read_text())
    return rows, world_checkpoint.load(world_checkpoint.table_path(out), config, EPISODES - 1)


def check_outcome(outcome: runs.Outcome, reference) -> None:
    """The run completed, every episode once, invariants held, nothing learned was lost."""
    assert outcome.fault_error is None, outcome.fault_error
    assert not outcome.timed_out, (outcome.timed_out, outcome.log("world")[-3000:])
    assert outcome.world_code == 0, outcome.log("world")[-3000:]
    for host, code in zip("ab", outcome.agent_codes):
        assert code == 0, outcome.log(host)[-3000:]
    assert [int(r["episode"]) for r in outcome.rows] == list(range(EPISODES))
    stats = json.loads((outcome.world_out / "stats" / "world.json").read_text())
    assert stats["completed"] and stats["violations"] == 0, stats
    assert "invariants" not in outcome.log("world")

    config = SwarmConfig.from_json((outcome.world_out / "config.json").read_text())
    assert config.shared
    shared = world_checkpoint.load(world_checkpoint.table_path(outcome.world_out), config,
                                   EPISODES - 1)
    for agent in range(AGENTS):
        where = outcome.agent_outs[0 if agent < AGENTS // 2 else 1]
        mine = read_fields(agent_checkpoint.checkpoint_path(where / "checkpoints", agent), ())
        assert np.array_equal(mine["q_ds"], shared[0]), agent
        assert np.array_equal(mine["q_ca"], shared[1]), agent

    rows, table = reference
    missed = [int(r["missed_intents"]) for r in outcome.rows]
    first_miss = next((i for i, m in enumerate(missed) if m), len(missed))
    first_short = min((int(episode) for episode in decided_short(outcome)), default=len(missed))
    same_until = min(first_miss, first_short)
    assert outcome.deterministic()[:same_until] == rows[:same_until]
    if same_until == len(missed):
        assert outcome.deterministic() == rows
        assert np.array_equal(shared[0], table[0]) and np.array_equal(shared[1], table[1])


def decided_short(outcome: runs.Outcome) -> set[str]:
    """The episodes in which some agent decided without an intent it needed."""
    return {episode for agent in range(AGENTS)
            for episode in json.loads(stats_path(outcome.agent_outs[0 if agent < AGENTS // 2
                                                                    else 1],
                                                 f"agent-{agent}").read_text())["decided_short"]}


def run_fault(name: str, lan, tmp_path: Path, port: int,
              run_options: tuple[str, ...] = ()) -> runs.Outcome:
    fault = runs.FAULTS[name]
    reason = runs.unavailable(fault)
    if reason is not None:
        pytest.skip(f"{fault.what}: cannot be made here: {reason}")
    return runs.run(lan, tmp_path, fault, agents=AGENTS, episodes=EPISODES, max_steps=MAX_STEPS,
                    seed=SEED, port=port, run_options=run_options)


def test_clean_run_equals_in_process(lan, reference, tmp_path):
    """The layout without a fault: the baseline every fault is checked like."""
    outcome = run_fault("clean", lan, tmp_path, 7701)
    check_outcome(outcome, reference)
    assert outcome.missed == 0 and decided_short(outcome) == set()


def test_netem_delay_jitter_reordering_and_loss(lan, reference, tmp_path):
    """5 ms ± 2 ms each way, a quarter of the packets overtaking the rest, 1 % lost."""
    outcome = run_fault("netem", lan, tmp_path, 7702)
    check_outcome(outcome, reference)


def test_delay_jitter_and_reordering_without_netem(lan, reference, tmp_path):
    """The same delay, jitter and reordering made in user space (tests/netdelay.py), where the
    kernel has no netem: every packet of the agents' hosts held 5 ms ± 2 ms, a quarter not."""
    outcome = run_fault("delay", lan, tmp_path, 7707)
    check_outcome(outcome, reference)
    assert outcome.held > 1000, "hardly a packet passed the delayer: the fault did not act"


def test_random_loss(lan, reference, tmp_path):
    """2 % of the agent hosts' packets lost, in and out: TCP resends them, late."""
    outcome = run_fault("loss", lan, tmp_path, 7703)
    check_outcome(outcome, reference)
    assert outcome.dropped > 0, "nothing was dropped: the fault did not act"


def test_partition_shorter_than_the_deadline(lan, reference, tmp_path):
    """Host a cut off for 1 s mid-run (the deadline is 2 s)."""
    outcome = run_fault("partition-short", lan, tmp_path, 7704)
    check_outcome(outcome, reference)
    assert outcome.fault_at_s is not None and outcome.rows_after_fault is not None, \
        "the partition did not fall inside the run"
    assert outcome.rows_after_fault < EPISODES


def test_partition_longer_than_the_deadline(lan, reference, tmp_path):
    """Host a cut off for 5 s mid-run: its agents' intents miss the ticks in between (they stay
    where they are), and the run goes on and completes once it is back."""
    outcome = run_fault("partition-long", lan, tmp_path, 7705)
    check_outcome(outcome, reference)
    assert outcome.fault_at_s is not None and outcome.rows_after_fault is not None, \
        "the partition did not fall inside the run"
    assert outcome.missed > 0, "5 s cut off and no intent missed a 2 s deadline?"


@pytest.mark.parametrize("config", [None, "config/client.json5"])
def test_router_restarted_mid_run(lan, reference, tmp_path, config):
    """The router killed outright mid-run and started again on its endpoint: the clients
    reconnect (at Zenoh's retry period, or config/client.json5's shorter one), and the run
    completes."""
    options = ("--zenoh-config", str(runs.ROOT / config)) if config else ()
    outcome = run_fault("router-restart", lan, tmp_path, 7706 if config is None else 7708,
                        options)
    check_outcome(outcome, reference)
    assert outcome.fault_at_s is not None and outcome.rows_after_fault is not None, \
        "the restart did not fall inside the run"
