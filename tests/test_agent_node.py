"""The agent process's adapter over a real (unconnected) Zenoh session: what it adds to the
protocol (tests/test_agent_machine.py) is carrying out effects and keeping bugs visible."""

import threading
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
        position=(1, 1), goal=(5, 5), neighbours=(), rank=0, reward_ds=0.0, reward_ca=10.0,
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
