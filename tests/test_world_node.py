"""The world process's adapter over a real (unconnected) Zenoh session: what it adds to the
protocol (tests/test_world_machine.py) is carrying out effects and keeping bugs visible."""

import threading
from types import SimpleNamespace

import pytest
import zenoh

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import WriteRow
from nnql_swarm.protocol.messages import Intent, agent_sender, encode
from nnql_swarm.transport.settings import TransportSettings
from nnql_swarm.world.world_node import WorldNode, WorldOptions

CONFIG = SwarmConfig(run_id="worldnode", n_agents=2, episodes=2, max_steps=5)


def intent_sample(agent: int, tick: int, action: int = 4, world: int = 1) -> SimpleNamespace:
    """What the handler reads of a zenoh.Sample (one cannot be built by hand): an intent
    decided for ``world``, the first start of the run's world (``transport.runfiles``)."""
    payload = encode(Intent(run="worldnode", tick=tick, sender=agent_sender(agent), agent=agent,
                            episode=0, action=action, world=world))
    return SimpleNamespace(key_expr=keys.intent_key("worldnode", agent), payload=payload)


@pytest.fixture
def node(tmp_path):
    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = WorldNode(WorldOptions(CONFIG, settings, tmp_path), session)
        assert node.world.incarnation == 1, "a fresh run folder: the world's first start"
        node.publishers = [session.declare_publisher(keys.obs_key("worldnode", i))
                           for i in range(CONFIG.n_agents)]
        for agent in range(CONFIG.n_agents):
            node.feed(node.protocol.on_liveliness,
                      keys.alive_key("worldnode", keys.ROLE_AGENT, agent), True)
        yield node


def test_the_last_intent_closes_the_tick_where_it_arrives_and_rows_go_to_the_main_thread(node):
    ticks = []
    node.on_tick = lambda world, report: ticks.append(report.tick)
    for tick in range(CONFIG.max_steps + 1):
        for agent in (0, 1):
            node._on_intent(intent_sample(agent, tick))
        assert node.world.tick == tick + 1
    assert ticks == list(range(CONFIG.max_steps + 1)), "every closed tick reached on_tick"
    kind, row = node.events.get_nowait()
    assert kind is WriteRow and row.row["episode"] == 0 and node.writer is None


def test_a_bug_while_closing_a_tick_on_zenohs_thread_stops_the_world(node):
    def broken(actions, learned=None, orders=None):
        raise RuntimeError("a bug in the rules")

    node.world.apply = broken
    node._on_intent(intent_sample(0, 0))
    zenoh_thread = threading.Thread(target=node._on_intent, args=(intent_sample(1, 0),))
    zenoh_thread.start()
    zenoh_thread.join()
    assert node.stopping
    assert isinstance(node.failure, RuntimeError)
