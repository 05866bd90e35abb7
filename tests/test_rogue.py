"""Bad input on the wire: a rogue Zenoh session floods every key the swarm listens on.

The swarm runs with a fixed world port; as soon as its agents are up a rogue peer joins the
mesh and sends garbage bytes, wrong types, oversized payloads, forged senders, other run ids,
stale and future ticks, bad and future intent queries, unknown liveliness tokens, and floods of
all that.
The run must complete with exactly the metrics of a clean in-process run of the same config (the
state is unchanged), and every rejection must be counted with its reason.
"""

import json
import os
import signal
import time

import pytest

import msgpack
import zenoh

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.messages import (
    WORLD_SENDER, Control, Intent, Observation, agent_sender, encode, to_wire,
)
from nnql_swarm.transport.ports import free_port
from nnql_swarm.transport.settings import TransportSettings
from tests.swarm_helpers import group_pids, run_swarm, start_swarm
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

RUN_ID = "rogue"
AGENTS = 6
EPISODES = 200  # long enough that the swarm outlives the attack, however fast it runs
OPTIONS = ("--agents", str(AGENTS), "--episodes", str(EPISODES), "--max-steps", "40", "--seed",
           "5", "--run-id", RUN_ID, "--deadline", "5", "--no-record")


def forged_payloads(agent: int) -> dict[str, list[bytes]]:
    """Every kind of bad message, for an observation key and an intent key of ``agent``."""
    obs = Observation(run=RUN_ID, tick=1, sender=WORLD_SENDER, agent=agent, episode=0, step=0,
                      position=(1, 1), goal=(2, 2), neighbours=b"", rank=0, reward_ds=0.0,
                      reward_ca=0.0, collided=False, arrived=False, episode_end=False)
    intent = Intent(run=RUN_ID, tick=1, sender=agent_sender(agent), agent=agent, episode=0, action=1)
    garbage = [b"", b"\x00\xff\xfe garbage", b"\xc1", os.urandom(64), b"\x92\x01", b"x" * 100_000]
    shutdown = Control(run=RUN_ID, tick=1, sender=WORLD_SENDER, command="shutdown")
    wrong_types = [msgpack.packb(v) for v in ([1, 2, 3], "obs", 3.5, None, {"v": "1"}, {1: 2})]
    wrong_types.append(msgpack.packb({"v": 1, "k": "intent", "r": RUN_ID, "t": 1}))  # version 1

    def mutated(msg, **changes) -> bytes:
        """The wire array of ``msg`` with some items changed: ``tag`` or fields."""
        wire = to_wire(msg)
        names = ("tag", *type(msg).__struct_fields__)
        for name, value in changes.items():
            wire[names.index(name)] = value
        return msgpack.packb(wire)

    bad_obs = [
        mutated(obs, sender="agent/3"),  # forged sender
        mutated(obs, run="another-run"),
        mutated(obs, tick=0),  # stale tick
        mutated(obs, tick=10**12),  # future tick
        mutated(obs, agent=(agent + 1) % AGENTS),  # someone else's observation
        mutated(obs, position=[True, 2]), mutated(obs, reward_ds=float("nan")),
        mutated(obs, tag="obs/99"), mutated(obs, neighbours=[[agent, 1, 1]]),
        msgpack.packb(to_wire(obs)[:-1]), msgpack.packb([*to_wire(obs), 0]),  # wrong lengths
    ]
    bad_intents = [
        mutated(intent, sender=agent_sender((agent + 1) % AGENTS)),  # forged sender
        mutated(intent, agent=(agent + 1) % AGENTS,
                sender=agent_sender((agent + 1) % AGENTS)),  # on the wrong key
        mutated(intent, run="another-run"),
        mutated(intent, tick=0), mutated(intent, tick=10**12),  # stale and future ticks
        mutated(intent, action=7), mutated(intent, action=True), mutated(intent, tag="obs/7"),
        msgpack.packb(to_wire(intent)[:-1]),  # wrong length
        encode(shutdown),
    ]
    bad_control = [mutated(shutdown, sender=agent_sender(agent)),
                   mutated(shutdown, run="another-run"),
                   mutated(shutdown, command="reboot"),
                   msgpack.packb({"v": 1, "k": "control", "c": "reboot"})]
    return {
        "obs": garbage + wrong_types + bad_obs,
        "intent": garbage + wrong_types + bad_intents,
        "control": garbage + wrong_types + bad_control,
    }


def attack(port: int, rounds: int) -> int:
    """Join the swarm's mesh and send every bad message ``rounds`` times; returns messages sent."""
    transport = TransportSettings(mode="peer", listen=("tcp/127.0.0.1:0",),
                                  connect=(f"tcp/127.0.0.1:{port}",))
    sent = 0
    with zenoh.open(transport.zenoh_config()) as session:
        # Peers do not forward for each other: wait until the mesh has linked the rogue to every
        # agent (their liveliness tokens arrive over those links), as an agent itself does.
        seen = set()
        with session.liveliness().declare_subscriber(
                keys.alive_key_all(RUN_ID, keys.ROLE_AGENT),
                lambda sample: seen.add(str(sample.key_expr)), history=True):
            deadline = time.monotonic() + 30
            while len(seen) < AGENTS and time.monotonic() < deadline:
                time.sleep(0.05)
        assert len(seen) == AGENTS, f"the rogue saw only {sorted(seen)}"
        tokens = [session.liveliness().declare_token(f"{keys.PREFIX}/{RUN_ID}/alive/agent/{name}")
                  for name in ("999", "x", "0042")]
        for _ in range(rounds):
            for agent in range(AGENTS):
                payloads = forged_payloads(agent)
                for payload in payloads["obs"]:
                    session.put(keys.obs_key(RUN_ID, agent), payload)
                for payload in payloads["intent"]:
                    session.put(keys.intent_key(RUN_ID, agent), payload)
                for payload in payloads["control"]:
                    session.put(keys.control_key(RUN_ID), payload)
                sent += sum(len(p) for p in payloads.values())
                for params in ("tick=abc", "", "tick=-1", "tick=99999999999", "tick=1;tick=2"):
                    for reply in session.get(f"{keys.intent_key(RUN_ID, agent)}?{params}",
                                             timeout=0.5):
                        pass
                    sent += 1
        for token in tokens:
            token.undeclare()
    return sent


def test_a_rogue_session_changes_nothing_and_every_rejection_is_counted(tmp_path):
    port = free_port()
    out = tmp_path / "attacked"
    swarm = start_swarm(out, *OPTIONS, "--port", str(port))
    try:
        # As soon as every agent is up (attack waits for them), often before the first tick: an
        # agent takes its first observation's tick at its word, and one that arrived in an
        # episode takes that episode's later ticks without a gap; a far tick forged for either
        # once stalled the run (agent_machine._past_its_episode, _skipped_while_quiet).
        sent = attack(port, rounds=5)
        assert swarm.poll() is None, "the run ended before the attack"
        stderr = swarm.finish(timeout=240)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 0, stderr
    assert "Traceback" not in stderr
    clean = run_swarm(tmp_path / "clean", *OPTIONS, "--in-process")
    assert clean.returncode == 0, clean.stderr

    def metrics(path):
        return [tuple(r[f] for f in EPISODE_FIELDS) for r in read_episodes(path / "episodes.csv")]

    assert metrics(out) == metrics(tmp_path / "clean"), "the rogue changed the run"
    world = json.loads((out / "stats" / "world.json").read_text())
    agents = [json.loads((out / "stats" / f"agent-{i}.json").read_text()) for i in range(AGENTS)]
    rejected_by_agents = sum(sum(a["rejected"].values()) for a in agents)
    rejected_by_world = sum(world["rejected"].values())
    assert sent > 1000
    assert rejected_by_world >= 5 * AGENTS * 20, world["rejected"]
    assert rejected_by_agents >= 5 * AGENTS * 30, [a["rejected"] for a in agents]
    for reason in ("not-msgpack", "not-array", "wrong-length", "oversize", "forged-sender",
                   "wrong-run", "stale-tick", "future-tick", "unknown-agent"):
        assert world["rejected"].get(reason, 0) > 0, (reason, world["rejected"])
    seen_by_agents = set().union(*(a["rejected"] for a in agents))
    for reason in ("not-msgpack", "not-array", "wrong-length", "oversize", "forged-sender",
                   "wrong-run", "stale-tick", "future-tick", "wrong-agent", "bad-query",
                   "future-query"):
        assert reason in seen_by_agents, (reason, seen_by_agents)
    assert all(a["shutdown_by_world"] for a in agents), "no forged shutdown was obeyed"
