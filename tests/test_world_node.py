"""The world process's intent handling, on a real (unconnected) Zenoh session."""

import threading
from types import SimpleNamespace

import pytest
import zenoh

from protocol import keys
from protocol.config import SwarmConfig
from protocol.messages import Intent, agent_sender, encode
from protocol.transport import TransportSettings
from world.node import WorldNode, WorldOptions

CONFIG = SwarmConfig(run_id="worldnode", n_agents=2, episodes=2, max_steps=5)


def intent_sample(agent: int, tick: int, action: int = 4) -> SimpleNamespace:
    """What the handler reads of a zenoh.Sample (one cannot be built by hand)."""
    payload = encode(Intent(run="worldnode", tick=tick, sender=agent_sender(agent), agent=agent,
                            episode=0, action=action))
    return SimpleNamespace(key_expr=keys.intent_key("worldnode", agent), payload=payload)


@pytest.fixture
def node(tmp_path):
    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = WorldNode(WorldOptions(CONFIG, settings, tmp_path), session)
        node.publishers = [session.declare_publisher(keys.obs_key("worldnode", i))
                           for i in range(CONFIG.n_agents)]
        node.alive = {0, 1}
        with node.lock:
            node._open_tick()
        yield node


def test_the_last_intent_closes_the_tick_where_it_arrives_once_the_last_one_is_logged(node):
    node.on_tick = lambda world, report: None  # as when recording: every tick is logged
    node._on_intent_sample(intent_sample(0, 0))
    assert node.world.tick == 0 and node.actions == [4, None]
    node._on_intent_sample(intent_sample(1, 0))
    assert node.world.tick == 1 and node.unlogged == 1  # closed, the next tick open
    assert node.events.get_nowait()[0] == "closed"
    for agent in (0, 1):
        node._on_intent_sample(intent_sample(agent, 1))
    assert node.world.tick == 1, "a tick closes only once the one before it is logged"
    node.unlogged = 0
    with node.lock:
        node._close_if_due()
    assert node.world.tick == 2
    node._on_intent_sample(intent_sample(0, 0))
    assert node.inbox.rejections["stale-tick"] == 1


def test_only_ticks_with_something_to_write_or_log_wake_the_main_thread(node):
    for tick in range(CONFIG.max_steps):  # nothing to record, nobody arrives in 5 steps
        for agent in (0, 1):
            node._on_intent_sample(intent_sample(agent, tick))
        assert node.world.tick == tick + 1 and node.unlogged == 0 and node.events.empty()
    for agent in (0, 1):  # the episode's end tick: its row is for the main thread to write
        node._on_intent_sample(intent_sample(agent, CONFIG.max_steps))
    kind, (report, slowest, _) = node.events.get_nowait()
    assert kind == "closed" and report.episode_row is not None and node.unlogged == 1
    assert report.episode_row["steps"] == CONFIG.max_steps and slowest > 0
    assert node.slowest == 0.0, "the next episode's slowest tick starts afresh"


def test_a_bug_while_closing_a_tick_on_zenohs_thread_stops_the_world(node):
    def broken(actions, learned=None):
        raise RuntimeError("a bug in the rules")

    node.world.apply = broken
    node._on_intent_sample(intent_sample(0, 0))
    zenoh_thread = threading.Thread(target=node._on_intent_sample, args=(intent_sample(1, 0),))
    zenoh_thread.start()
    zenoh_thread.join()
    assert node.stopping
    assert isinstance(node.failure, RuntimeError)
