"""The world process's adapter over a real (unconnected) Zenoh session: what it adds to the
protocol (tests/test_world_machine.py) is carrying out effects and keeping bugs visible."""

import errno
import threading
from contextlib import contextmanager
from dataclasses import replace
from types import SimpleNamespace

import pytest
import zenoh

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import WriteRow
from nnql_swarm.protocol.messages import Intent, agent_sender, encode
from nnql_swarm.transport.settings import TransportSettings
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.world_node import WorldNode, WorldOptions

CONFIG = SwarmConfig(run_id="worldnode", n_agents=2, episodes=2, max_steps=5)


def intent_sample(agent: int, tick: int, action: int = 4, world: int = 1,
                  episode: int = 0) -> SimpleNamespace:
    """What the handler reads of a zenoh.Sample (one cannot be built by hand): an intent
    decided for ``world``, the first start of the run's world (``transport.runfiles``)."""
    payload = encode(Intent(run="worldnode", tick=tick, sender=agent_sender(agent), agent=agent,
                            episode=episode, action=action, world=world))
    return SimpleNamespace(key_expr=keys.intent_key("worldnode", agent), payload=payload)


@contextmanager
def world_node(tmp_path, config: SwarmConfig = CONFIG):
    """A world node whose agents are all alive, over an unconnected session."""
    settings = TransportSettings(mode="peer")
    with zenoh.open(settings.zenoh_config()) as session:
        node = WorldNode(WorldOptions(config, settings, tmp_path), session)
        assert node.world.incarnation == 1, "a fresh run folder: the world's first start"
        node.publishers = [session.declare_publisher(keys.obs_key("worldnode", i))
                           for i in range(config.n_agents)]
        for agent in range(config.n_agents):
            node.feed(node.protocol.on_liveliness,
                      keys.alive_key("worldnode", keys.ROLE_AGENT, agent), True)
        yield node


@pytest.fixture
def node(tmp_path):
    with world_node(tmp_path) as node:
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


def test_once_a_row_cannot_be_written_no_later_episode_is(tmp_path, monkeypatch):
    """A full disk: the first episode's row fails while the second's is queued behind it. The
    second's checkpoint, rewritten in place, would succeed where its row fails, and leave the
    shared table's checkpoint two episodes ahead of the rows, which no resume accepts."""
    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(EpisodeWriter, "write", full)
    with world_node(tmp_path, replace(CONFIG, episodes=3)) as node:
        ticks = CONFIG.max_steps + 1
        for episode in (0, 1):
            for tick in range(episode * ticks, (episode + 1) * ticks):
                for agent in (0, 1):
                    node._on_intent(intent_sample(agent, tick, episode=episode))
        assert node.failure is None and node.events.qsize() == 2, "both episodes' rows queued"
        with pytest.raises(OSError, match="No space"):
            node.run()
        assert world_checkpoint.episodes(node.table_file) == [0], "nothing after the failed row"
