"""The agent process's adapter over a real (unconnected) Zenoh session: what it adds to the
protocol (tests/test_agent_machine.py) is carrying out effects and keeping bugs visible."""

import threading
from pathlib import Path
from types import SimpleNamespace

import zenoh

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.agent.agent_node import AgentNode, AgentOptions
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.messages import WORLD_SENDER, Observation, encode
from nnql_swarm.transport.settings import TransportSettings

CONFIG = SwarmConfig(run_id="node", n_agents=1, episodes=10, max_steps=50)


def observation(tick: int, episode_end: bool = False) -> SimpleNamespace:
    """What the handler reads of a zenoh.Sample (one cannot be built by hand)."""
    return SimpleNamespace(payload=encode(Observation(
        run="node", tick=tick, sender=WORLD_SENDER, agent=0, episode=0, step=tick % 50,
        position=(1, 1), goal=(5, 5), neighbours=b"", rank=0, reward_ds=0.0, reward_ca=10.0,
        collided=False, arrived=False, episode_end=episode_end)))


def test_effects_are_carried_out_in_order_an_episodes_checkpoint_before_its_intent(tmp_path):
    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = AgentNode(AgentOptions(0, CONFIG, settings, tmp_path), session)
        seen = []

        class Watched:
            """The node's publisher, noting whether the checkpoint is there at each put."""

            def __init__(self, publisher) -> None:
                self.publisher = publisher

            def put(self, payload: bytes) -> None:
                seen.append(node.checkpoint_file.exists())
                self.publisher.put(payload)

        with session.declare_publisher(keys.intent_key("node", 0)) as publisher:
            node.publisher = Watched(publisher)
            node._on_observation(observation(0))
            node._on_observation(observation(1, episode_end=True))
        assert node.protocol.decided_tick == 1
        assert seen == [False, True], "the checkpoint was written before the intent went out"


def test_a_bug_in_a_handler_on_zenohs_thread_stops_the_agent_instead_of_vanishing(tmp_path):
    class BrokenBrain(AgentBrain):
        def act(self, obs, answers, seen=(None, None)):
            raise RuntimeError("a bug in the brain")

    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = AgentNode(AgentOptions(0, CONFIG, settings, tmp_path), session,
                         BrokenBrain(0, CONFIG))
        zenoh_thread = threading.Thread(target=node._on_observation, args=(observation(0),))
        zenoh_thread.start()
        zenoh_thread.join()
        assert node.stopping
        assert isinstance(node.failure, RuntimeError)
        node._on_observation(observation(1))  # a stopping agent handles nothing more
        assert node.protocol.decided_tick == -1 and node.protocol.inbox.accepted == 1


def _rejoining_agent(layout, out_dir: str) -> int:
    """An agent process of a swarm of two whose other agent never comes: every session it opens
    hears no other agent."""
    from dataclasses import replace

    from nnql_swarm.agent.agent_node import run_agent

    config = SwarmConfig(run_id="rejoin", n_agents=2, episodes=1, max_steps=5)
    transport = replace(layout.agent(), rejoin_deaf_s=0.5)
    return run_agent(AgentOptions(0, config, transport, Path(out_dir)))


def test_an_agent_whose_session_hears_no_other_agent_opens_another_then_keeps_the_last(tmp_path):
    """In the launcher's hub layout, an agent that hears no other agent within ``rejoin_deaf_s``
    opens a new session (the hub sees its token go and come back), REJOINS times, then keeps
    the last one and waits for its peers as ever, until the world's shutdown."""
    import multiprocessing as mp
    import time

    from nnql_swarm.agent.agent_node import REJOINS
    from nnql_swarm.protocol.messages import Control
    from nnql_swarm.transport.settings import open_session
    from nnql_swarm.transport.topology import REJOIN_DEAF_S, EmbeddedLayout

    layout = EmbeddedLayout(topology="hub-peer")
    assert layout.agent().rejoin_deaf_s == REJOIN_DEAF_S > 0 and layout.world().rejoin_deaf_s == 0
    assert EmbeddedLayout(topology="mesh").agent().rejoin_deaf_s == 0
    comings = []
    with open_session(layout.world()) as hub, hub.liveliness().declare_subscriber(
            keys.alive_key("rejoin", keys.ROLE_AGENT, 0),
            lambda sample: comings.append(sample.kind == zenoh.SampleKind.PUT), history=True):
        process = mp.get_context("spawn").Process(target=_rejoining_agent,
                                                  args=(layout, str(tmp_path)))
        process.start()
        deadline = time.monotonic() + 60
        while comings.count(True) < REJOINS + 1 and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(1.0)  # the last session is kept: no more comings
        hub.put(keys.control_key("rejoin"), encode(Control("rejoin", 0, WORLD_SENDER, "shutdown")))
        process.join(30)
    assert comings.count(True) == REJOINS + 1, comings
    assert comings[:2 * REJOINS] == [True, False] * REJOINS  # each deaf session closed
    assert process.exitcode == 0
