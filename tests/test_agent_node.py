"""The agent process's event handling, on a real (unconnected) Zenoh session: tick order rules."""

import threading

import zenoh

from agent.brain import AgentBrain
from agent.node import RESYNC_AFTER, AgentNode, AgentOptions
from protocol import keys
from protocol.config import SwarmConfig
from protocol.messages import WORLD_SENDER, Observation, encode
from protocol.transport import TransportSettings

CONFIG = SwarmConfig(run_id="node", n_agents=2, episodes=10, max_steps=50)


def observation(tick: int) -> bytes:
    return encode(Observation(
        run="node", tick=tick, sender=WORLD_SENDER, agent=0, episode=0, step=tick % 50,
        position=(1, 1), goal=(5, 5), neighbours=(), rank=0, reward_ds=0.0, reward_ca=10.0,
        collided=False, arrived=False, episode_end=False))


def test_ticks_must_follow_on_and_a_gap_is_crossed_only_by_a_run_of_observations(tmp_path):
    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = AgentNode(AgentOptions(0, CONFIG, settings, tmp_path), session)
        with session.declare_publisher(keys.intent_key("node", 0)) as publisher:
            node.publisher = publisher
            for tick in (0, 1, 2):
                node._on_observation(observation(tick))
            assert node.decided_tick == 2
            node._on_observation(observation(1))
            assert node.inbox.rejections["stale-tick"] == 1
            node._on_observation(observation(10**6))  # a lone far-future tick moves nothing
            node._on_observation(observation(3))
            assert node.decided_tick == 3
            gap = [10 + i for i in range(RESYNC_AFTER)]  # observations 4..9 were lost
            for tick in gap[:-1]:
                node._on_observation(observation(tick))
                assert node.decided_tick == 3
            node._on_observation(observation(gap[-1]))
            assert node.decided_tick == gap[-1]
            assert node.inbox.rejections["future-tick"] == RESYNC_AFTER


def test_a_bug_in_a_handler_on_zenohs_thread_stops_the_agent_instead_of_vanishing(tmp_path):
    class BrokenBrain(AgentBrain):
        def act(self, obs, answers):
            raise RuntimeError("a bug in the brain")

    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = AgentNode(AgentOptions(0, CONFIG, settings, tmp_path), session,
                         BrokenBrain(0, CONFIG))
        handler = node._guarded(node._on_observation)
        zenoh_thread = threading.Thread(target=handler, args=(observation(0),))
        zenoh_thread.start()
        zenoh_thread.join()
        assert node.stopping
        assert isinstance(node.failure, RuntimeError)
        handler(observation(1))  # a stopping agent handles nothing more
        assert node.decided_tick == -1 and node.inbox.accepted == 1
