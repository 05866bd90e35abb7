"""One agent's protocol machine, pure: inputs in, effects out, no network, no clock."""

import dataclasses
import math

import msgpack
import msgspec
import pytest

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.learning.fields import LS_PENDING
from nnql_swarm.agent.agent_machine import PEER_WAIT_S, RESYNC_AFTER, AgentMachine
from nnql_swarm.agent.answering import STANDING_UNSEEN_TICKS
from nnql_swarm.agent.negotiation import STREAM_MARGIN
from nnql_swarm.agent.phases import TRANSITIONS, Event, Phase
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import Ask, Checkpoint, EndQuery, Log, Reply, SendIntent, Stopped
from nnql_swarm.protocol.phase_machine import PhaseError
from nnql_swarm.world.world_machine import STARTUP_TIMEOUT_S, WorldMachine
from nnql_swarm.protocol.messages import (
    CONTROL_SHUTDOWN, WORLD_SENDER, Answer, Control, Observation, agent_sender, encode,
    pack_ids, pack_neighbours, pack_updates, to_wire,
)

CONFIG = SwarmConfig(run_id="proto", n_agents=3, episodes=20, max_steps=50)


def observation(tick: int, agent: int = 0, episode_end: bool = False, others=(),
                world: int = 0) -> bytes:
    """Agent ``agent``'s observation at ``tick``, in a run of episodes ``max_steps`` ticks
    long; ``others``: visible ``(id, x, y)``; ``world``: the incarnation of the world that
    sends it (one more each time the run's world starts)."""
    episode, step = divmod(tick, CONFIG.max_steps)
    return encode(Observation(
        run="proto", tick=tick, sender=WORLD_SENDER, agent=agent, episode=episode, step=step,
        position=(1, 1), goal=(5, 5), neighbours=pack_neighbours(others),
        rank=(agent - tick) % CONFIG.n_agents, reward_ds=0.0, reward_ca=10.0, collided=False,
        arrived=False, episode_end=episode_end, world=world))


def answer(tick: int, agent: int, action: int, relayed=()) -> bytes:
    return encode(Answer("proto", tick, agent_sender(agent), agent, 0, action, tuple(relayed)))


def ready(agent: int = 0, config: SwarmConfig = CONFIG) -> AgentMachine:
    """A protocol that has seen every peer."""
    protocol = AgentMachine(agent, config, AgentBrain(agent, config), now=0.0)
    for j in range(config.n_agents):
        protocol.on_liveliness(keys.alive_key(config.run_id, keys.ROLE_AGENT, j), True, 0.0)
    assert protocol.phase is Phase.IDLE
    return protocol


def kinds(effects) -> list[str]:
    return [type(e).__name__ for e in effects if not isinstance(e, Log)]


def test_ticks_must_follow_on_and_a_gap_is_crossed_only_by_a_run_of_observations():
    protocol = ready()
    for tick in (0, 1, 2):
        assert "SendIntent" in kinds(protocol.on_observation(observation(tick), 0.0))
    assert protocol.decided_tick == 2
    assert kinds(protocol.on_observation(observation(1), 0.0)) == []
    assert protocol.inbox.rejections["stale-tick"] == 1
    protocol.on_observation(observation(10**6), 0.0)  # a lone far-future tick moves nothing
    protocol.on_observation(observation(3), 0.0)
    assert protocol.decided_tick == 3
    gap = [10 + i for i in range(RESYNC_AFTER)]  # observations 4..9 were lost
    for tick in gap[:-1]:
        protocol.on_observation(observation(tick), 0.0)
        assert protocol.decided_tick == 3
    protocol.on_observation(observation(gap[-1]), 0.0)
    assert protocol.decided_tick == gap[-1]
    assert protocol.inbox.rejections["future-tick"] == RESYNC_AFTER


def test_observations_wait_for_the_peers_then_are_handled_in_order():
    protocol = AgentMachine(0, CONFIG, AgentBrain(0, CONFIG), now=5.0)
    assert protocol.timer() == 5.0 + PEER_WAIT_S
    assert protocol.on_observation(observation(0), 6.0) == []
    assert protocol.on_observation(observation(1), 6.0) == []
    for j in (0, 1):
        protocol.on_liveliness(keys.alive_key("proto", keys.ROLE_AGENT, j), True, 7.0)
    assert protocol.decided_tick == -1
    effects = protocol.on_timer(5.0 + PEER_WAIT_S)  # agent 2 never showed up
    assert kinds(effects).count("SendIntent") == 2 and protocol.decided_tick == 1


def test_the_wait_for_peers_grows_with_a_large_swarm():
    """Over a second per agent at start-up where that is longer than the fixed wait, as the world's
    wait for its agents: 128 spawned processes need about half a minute to come up."""
    large = SwarmConfig(run_id="proto", n_agents=128, width=45, height=45)
    assert AgentMachine(0, large, AgentBrain(0, large), now=5.0).timer() == 5.0 + 128 * 1.0
    assert WorldMachine(large, 5.0).timer() == 5.0 + 128 * 1.0
    assert WorldMachine(CONFIG, 5.0).timer() == 5.0 + STARTUP_TIMEOUT_S


def test_an_agent_that_hears_no_other_agent_stops_to_rejoin_where_told_to():
    """A session that hears no other agent's token by ``rejoin_deaf_s`` (at 512 agents a few
    sessions heard nobody, nor did anyone hear them) is taken for deaf: the agent stops to open
    another. Hearing any other agent, or being told nothing, it waits for the peers as ever."""
    own = keys.alive_key("proto", keys.ROLE_AGENT, 0)
    deaf = AgentMachine(0, CONFIG, AgentBrain(0, CONFIG), now=5.0, rejoin_deaf_s=3.0)
    assert deaf.timer() == 8.0
    deaf.on_liveliness(own, True, 5.5)  # its own token, which it hears without the hub
    assert deaf.on_timer(7.9) == [] and not deaf.stopped
    effects = deaf.on_timer(8.0)
    assert effects[-1] == Stopped(False, rejoin=True) and deaf.stopped
    assert "heard no other agent" in effects[0].message
    hearing = AgentMachine(0, CONFIG, AgentBrain(0, CONFIG), now=5.0, rejoin_deaf_s=3.0)
    hearing.on_liveliness(keys.alive_key("proto", keys.ROLE_AGENT, 2), True, 6.0)
    assert hearing.timer() == 5.0 + PEER_WAIT_S and hearing.on_timer(8.0) == []
    told_nothing = AgentMachine(0, CONFIG, AgentBrain(0, CONFIG), now=5.0)
    assert told_nothing.timer() == 5.0 + PEER_WAIT_S and told_nothing.on_timer(8.0) == []
    alone = SwarmConfig(run_id="proto", n_agents=1)
    assert AgentMachine(0, alone, AgentBrain(0, alone), now=5.0, rejoin_deaf_s=3.0).deaf_by is None


def test_an_agent_asks_and_decides_once_the_answer_is_in_or_the_time_is_up():
    protocol = ready(agent=1)
    # tick 0: agent 0 ranks first, agent 1 second; agent 1 sees agent 0 and waits for it
    effects = protocol.on_observation(observation(0, agent=1, others=[(0, 2, 2)]), 10.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    assert ask.agent == 0 and ask.parameters == "tick=0;from=1"
    assert protocol.timer() == 10.0 + CONFIG.tick_deadline_s / 2
    effects = protocol.on_answer(ask.ask, answer(0, agent=0, action=3), 10.1)
    [intent] = [e for e in effects if isinstance(e, SendIntent)]
    assert intent.intent.tick == 0 and protocol.decided_tick == 0
    assert protocol.stats()["decided_short"] == {}
    # tick 1: nobody outranks agent 1 that it sees (agent 0 is now last): it decides at once
    assert "SendIntent" in kinds(protocol.on_observation(observation(1, agent=1, others=[(0, 2, 2)]),
                                                         10.2))
    # tick 3: agent 0 first again; no answer comes: the time-out decides
    protocol.on_observation(observation(2, agent=1, others=[(0, 2, 2)]), 10.3)
    protocol.on_observation(observation(3, agent=1, others=[(0, 2, 2)]), 10.4)
    assert protocol.decided_tick == 2 and protocol.phase is Phase.NEGOTIATING
    assert protocol.on_timer(10.5) == []
    assert "SendIntent" in kinds(protocol.on_timer(protocol.timer()))
    assert protocol.decided_tick == 3
    assert protocol.stats()["decided_short"] == {0: 2}  # ticks 2 and 3, short of agent 0


def test_held_and_standing_queries_are_answered_with_the_decision_the_next_in_rank_first():
    protocol = ready(agent=0)
    held = protocol.on_query(7, "tick=0;from=2", 0.0)
    assert held == [] and protocol.held
    standing = protocol.on_query(8, "since=0;from=1", 0.0)
    assert standing == []
    effects = protocol.on_observation(observation(0, others=[(1, 2, 2), (2, 3, 3)]), 0.1)
    replies = [(type(e).__name__, e.query) for e in effects if isinstance(e, (Reply, EndQuery))]
    assert replies == [("Reply", 8), ("Reply", 7), ("EndQuery", 7)]  # the standing one stays
    [intent] = [e for e in effects if isinstance(e, SendIntent)]
    assert all(e.answer.action == intent.intent.action for e in effects if isinstance(e, Reply))
    # a newer standing query from the same asker replaces the old one
    assert protocol.on_query(9, "since=1;from=1", 0.2) == [EndQuery(8)]


def test_an_episodes_end_checkpoints_before_the_intent_goes_out():
    protocol = ready()
    effects = protocol.on_observation(observation(0, episode_end=True), 0.0)
    assert kinds(effects) == ["Checkpoint", "SendIntent", "EpisodeEnded"]  # nobody asked
    assert effects[0] == Checkpoint(0)


def test_standing_queries_go_to_the_agents_near_and_end_once_they_are_far():
    """An agent opens a standing query on every agent within the interaction radius and
    STREAM_MARGIN once it has decided (one not yet streamed is asked directly); the agent
    streamed from keeps it while the asker is that near and ends it once it has been farther for
    STANDING_UNSEEN_TICKS decided ticks."""
    reach = CONFIG.interaction_radius + STREAM_MARGIN
    near, far = (1 + reach, 1), (2 + reach, 1)  # seen from (1, 1), where observation() puts it
    asker, answerer = ready(agent=1), ready(agent=0)
    # tick 0: agent 0 outranks agent 1, which sees it: a direct ask, then a stream from tick 1
    effects = asker.on_observation(observation(0, agent=1, others=[(0, 2, 2)]), 0.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    assert ask.parameters == "tick=0;from=1"
    effects = asker.on_answer(ask.ask, answer(0, agent=0, action=3), 0.1)
    [stream] = [e for e in effects if isinstance(e, Ask)]
    assert (stream.agent, stream.parameters) == (0, "since=1;from=1") and asker.streams == {0: 1}
    # agent 1 ranks first at tick 1 and decides at once: a stream on agent 2, just near enough
    effects = asker.on_observation(observation(1, agent=1, others=[(0, 2, 2), (2, *near)]), 0.2)
    assert [(e.agent, e.parameters) for e in effects if isinstance(e, Ask)] == [
        (2, "since=2;from=1")]
    effects = asker.on_observation(observation(2, agent=1, others=[(2, *far)]), 0.2)
    assert kinds(effects) == ["SendIntent"], "no stream on an agent farther away"
    assert answerer.on_query(stream.ask, stream.parameters, 0.1) == []
    # agent 0 keeps the stream while agent 1 is near, however long it goes unasked
    for tick in range(1, STANDING_UNSEEN_TICKS + 3):
        effects = answerer.on_observation(observation(tick, others=[(1, *near)]), 0.3)
        assert not any(isinstance(e, EndQuery) for e in effects)
    # and ends it once agent 1 has been farther for STANDING_UNSEEN_TICKS decided ticks
    ended = []
    for tick in range(STANDING_UNSEEN_TICKS + 3, 2 * STANDING_UNSEEN_TICKS + 6):
        ended += [(tick, e) for e in answerer.on_observation(
            observation(tick, others=[(1, *far)]), 0.4) if isinstance(e, EndQuery)]
    last_near = STANDING_UNSEEN_TICKS + 2
    assert ended == [(last_near + STANDING_UNSEEN_TICKS + 1, EndQuery(stream.ask))]
    assert answerer.standing == {}
    assert asker.on_ask_end(stream.ask, 0.5) == [] and asker.streams == {2: 2}


def test_a_standing_query_is_ended_counting_from_the_ticks_a_world_that_came_back_replays():
    """A world that comes back (``--resume``) numbers its ticks again from its checkpoint: an
    asker last near at a later tick is taken as near at the first replayed tick, so its standing
    query ends STANDING_UNSEEN_TICKS decided ticks after that one, not never; one opened
    since a tick ahead is counted from the decided tick likewise."""
    answerer = ready(agent=0)
    for tick in range(300, 303):
        answerer.on_observation(observation(tick, others=[(1, 2, 2)]), 0.1)
    assert answerer.on_query(7, "since=303;from=1", 0.2) == []
    assert answerer.on_query(8, "since=900;from=2", 0.2) == []  # far ahead
    answerer.on_world(False, 1.0)
    answerer.on_world(True, 2.0)
    ended = []
    for tick in range(0, STANDING_UNSEEN_TICKS + 3):  # the world started again
        ended += [(tick, e) for e in answerer.on_observation(observation(tick, world=1), 3.0)
                  if isinstance(e, EndQuery)]
    assert sorted(ended, key=lambda e: e[1].query) == [
        (STANDING_UNSEEN_TICKS + 1, EndQuery(7)), (STANDING_UNSEEN_TICKS + 1, EndQuery(8))]


def test_a_tick_decided_before_the_world_left_is_never_decided_again():
    """Once the world left, an agent takes its next observation at its word; a copy of a tick it
    decided for that world, still on its way, is refused (``stale-tick``), so its announced
    intent never changes (fault schedule 110146 of 16 agents: a duplicate arrived after the
    world left, and the agent decided that tick again, differently). The same world reached
    again goes on from later ticks; a world started again replays its ticks as its own."""
    protocol = ready(agent=0)
    for tick in range(3):
        assert "SendIntent" in kinds(protocol.on_observation(observation(tick), 0.1))
    protocol.on_world(False, 1.0)
    assert kinds(protocol.on_observation(observation(2), 1.1)) == []
    assert kinds(protocol.on_observation(observation(1), 1.1)) == []
    assert protocol.inbox.rejections["stale-tick"] == 2 and protocol.decided_tick == -1
    protocol.on_world(False, 1.2)  # the token again: what was decided is still known
    assert kinds(protocol.on_observation(observation(2), 1.3)) == []
    assert "SendIntent" in kinds(protocol.on_observation(observation(3), 1.4))  # the same world
    protocol.on_world(False, 2.0)
    protocol.on_world(True, 3.0)
    assert "SendIntent" in kinds(protocol.on_observation(observation(1, world=1), 3.1))
    assert protocol.decided_tick == 1 and protocol.inbox.rejections["stale-tick"] == 3


def test_a_settled_agent_sends_the_world_no_intent_unless_it_has_a_record():
    """An observation that says the agent is settled (one that catches its table up) is
    decided (STAY); the world expects no intent for it, so none goes out, unless the agent has a
    learning record to deliver (its arrival observation was lost on the way)."""
    protocol = ready(agent=0)

    def settled(tick: int, arrived_before: bool) -> bytes:
        return encode(Observation(
            run="proto", tick=tick, sender=WORLD_SENDER, agent=0, episode=0, step=tick,
            position=(5, 5), goal=(5, 5), neighbours=pack_neighbours([(1, 6, 6)]), rank=0,
            reward_ds=0.0, reward_ca=10.0, collided=False, arrived=True, episode_end=False,
            settled=arrived_before))

    moving = protocol.on_observation(observation(0, others=[(1, 6, 6)]), 0.0)
    assert "SendIntent" in kinds(moving) and protocol.brain.learner.state[LS_PENDING] == 1
    late = protocol.on_observation(settled(1, arrived_before=True), 0.1)  # tick 0's outcome
    [record] = [e for e in late if isinstance(e, SendIntent)]
    assert record.intent.action == 4 and record.intent.record, "the lost arrival's record"
    quiet = protocol.on_observation(settled(5, arrived_before=True), 0.2)
    assert "SendIntent" not in kinds(quiet) and protocol.decided_tick == 5


@pytest.mark.parametrize("wait_rule", ["meet", "reach"])
def test_once_arrived_under_meet_a_skipped_tick_is_no_gap(wait_rule):
    """Under ``meet`` the world sends a settled agent nothing until the episode's end tick, so
    after its arrived observation a later tick of that episode is taken at once; under
    ``reach``, and into another episode, a jump is a gap as ever (RESYNC_AFTER in a row)."""
    protocol = ready(agent=0, config=dataclasses.replace(CONFIG, wait_rule=wait_rule))

    def at(tick: int, episode: int = 0, arrived: bool = True, end: bool = False) -> bytes:
        return encode(Observation(
            run="proto", tick=tick, sender=WORLD_SENDER, agent=0, episode=episode, step=tick,
            position=(5, 5), goal=(5, 5), neighbours=b"", rank=0, reward_ds=0.0, reward_ca=10.0,
            collided=False, arrived=arrived, episode_end=end))

    protocol.on_observation(at(3), 0.0)
    assert protocol.decided_tick == 3
    protocol.on_observation(at(9, end=True), 0.1)
    assert protocol.decided_tick == (9 if wait_rule == "meet" else 3)
    protocol.on_observation(at(20, episode=1, arrived=False), 0.2)
    assert protocol.decided_tick == (9 if wait_rule == "meet" else 3), "another episode: a gap"



def at_step(tick: int, step: int, episode: int = 0, arrived: bool = True) -> bytes:
    """Agent 0's observation at ``tick``, ``step`` of ``episode``, on its goal."""
    return encode(Observation(
        run="proto", tick=tick, sender=WORLD_SENDER, agent=0, episode=episode, step=step,
        position=(5, 5), goal=(5, 5), neighbours=b"", rank=0, reward_ds=0.0, reward_ca=10.0,
        collided=False, arrived=arrived, episode_end=False))


def test_an_observation_no_world_of_the_run_could_send_sets_no_clock():
    """An agent takes its first observation at its word, whatever its tick, but not one past
    what its episode can reach (``SwarmConfig.episode_ticks`` a episode from tick 0), a step
    past ``max_steps`` or an episode past the run's: the rogue test's ``tick=10**12``, sent
    before the run's first tick, once stalled the agent for good."""
    protocol = ready(agent=0)
    last = CONFIG.episodes - 1
    for forged in (at_step(10**12, 0), at_step(10**12, 10**12 - 1),
                   at_step(CONFIG.max_steps + 1, CONFIG.max_steps + 1),
                   at_step(2 * CONFIG.episode_ticks + 1, 0, episode=2),
                   at_step(CONFIG.episodes * CONFIG.episode_ticks, 0, episode=CONFIG.episodes)):
        assert kinds(protocol.on_observation(forged, 0.0)) == []
    assert protocol.decided_tick == -1
    assert protocol.inbox.rejections["future-tick"] == 5
    protocol.on_observation(at_step(last * CONFIG.episode_ticks + 3, 3, episode=last), 0.1)
    assert protocol.decided_tick == last * CONFIG.episode_ticks + 3, "the latest a run reaches"


def test_a_far_tick_forged_for_the_quiet_episode_does_not_move_the_clock():
    """Once arrived under ``meet``, a later tick of that episode is taken at once, but only one
    of that episode: the same first tick (``tick - step``). Agents that arrived in an early
    episode once took any tick forged for it, and stalled."""
    protocol = ready(agent=0, config=dataclasses.replace(CONFIG, wait_rule="meet"))
    protocol.on_observation(at_step(93, 3, episode=2), 0.0)  # episode 2 began at tick 90
    assert protocol.decided_tick == 93
    protocol.on_observation(at_step(100, 0, episode=2), 0.1)  # within reach, not from tick 90
    assert protocol.decided_tick == 93
    assert protocol.inbox.rejections["future-tick"] == 1
    protocol.on_observation(at_step(97, 7, episode=2), 0.2)  # ticks 94 to 96 skipped by the world
    assert protocol.decided_tick == 97


def test_answers_from_before_the_world_left_do_not_count_for_the_world_that_comes_back():
    """A world resumed under running agents replays tick numbers: an answer still on its way
    from the world before must not count for the new one."""
    protocol = ready(agent=1)
    effects = protocol.on_observation(observation(0, agent=1, others=[(0, 2, 2)]), 0.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    protocol.on_world(False, 0.1)
    assert protocol.on_answer(ask.ask, answer(0, agent=0, action=3), 0.2) == []
    effects = protocol.on_observation(observation(0, agent=1, others=[(0, 2, 2)]), 1.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    effects = protocol.on_answer(ask.ask, answer(0, agent=0, action=1), 1.1)
    assert any(isinstance(e, SendIntent) for e in effects) and protocol.decided_tick == 0
    assert protocol.decided_answer.relayed == ((0, 1),), "the new world's answer, not the old"


def test_a_standing_query_that_ends_mid_negotiation_is_replaced_by_a_direct_ask():
    """A standing query that ends while the agent waits for its answer is replaced by a direct
    ask at once, not waited out to the negotiation's time-out."""
    protocol = ready(agent=1)
    others = [(0, 2, 2)]
    protocol.on_observation(observation(1, agent=1, others=others), 0.0)  # decides: it is first
    [stream] = [a for a, open_ask in protocol.asks.items()
                if open_ask.generation is not None and open_ask.agent == 0]
    effects = protocol.on_observation(observation(2, agent=1, others=others), 0.1)  # 0 first: waits
    assert protocol.phase is Phase.NEGOTIATING and not any(isinstance(e, Ask) for e in effects)
    assert not any(
        isinstance(e, Ask) for e in protocol.on_answer(stream, answer(1, 0, 2), 0.1))
    effects = protocol.on_ask_end(stream, 0.2)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    assert ask.agent == 0 and ask.parameters == "tick=2;from=1"


def test_the_worlds_shutdown_stops_the_agent_and_finishes_its_queries():
    protocol = ready()
    protocol.on_query(4, "tick=5;from=1", 0.0)
    protocol.on_query(5, "since=5;from=2", 0.0)
    wire = to_wire(Control("proto", 1, WORLD_SENDER, CONTROL_SHUTDOWN))
    wire[3] = agent_sender(1)  # an agent sending the world's shutdown
    assert kinds(protocol.on_control(msgpack.packb(wire), 0.0)) == []
    assert protocol.phase is Phase.IDLE
    effects = protocol.on_control(encode(Control("proto", 1, WORLD_SENDER, CONTROL_SHUTDOWN)), 0.0)
    assert [e for e in effects if not isinstance(e, Log)] == [EndQuery(4), EndQuery(5),
                                                              Stopped(by_world=True)]
    assert protocol.shutdown and protocol.timer() is None
    assert protocol.on_query(6, "tick=5;from=1", 0.0) == [EndQuery(6)]


def test_bad_input_is_counted_never_raised():
    protocol = ready()
    for payload in (b"", b"\xc1", b"garbage", observation(0, agent=2)):
        assert kinds(protocol.on_observation(payload, 0.0)) == []
    for parameters in ("", "tick=abc", "since=1", "since=1;from=0", "since=1;from=99"):
        effects = protocol.on_query(1, parameters, 0.0)
        assert kinds(effects) == ["ReplyError", "EndQuery"], parameters
    assert kinds(protocol.on_liveliness("nnql/proto/alive/agent/0042", True, 0.0)) == []
    assert protocol.on_answer(12345, b"garbage", 0.0) == []
    assert protocol.inbox.total_rejected >= 10


def test_an_observation_that_does_not_fit_the_run_is_refused_before_any_kernel_reads_it():
    """The codec bounds ids and cells by the wire's limits, not by the run's, and checks only
    that the packed neighbours are whole; the decision and the plan, compiled, read their buffers
    unchecked: so an observation naming an agent the run has not, a cell off its grid, a
    neighbour twice or the agent itself, is refused and counted, and decides nothing."""
    protocol = ready()
    assert CONFIG.width == CONFIG.height == 11

    def forged(**fields) -> bytes:
        obs = Observation(run="proto", tick=0, sender=WORLD_SENDER, agent=0, episode=0, step=0,
                          position=(1, 1), goal=(5, 5), neighbours=pack_neighbours([(1, 2, 2)]),
                          rank=0, reward_ds=0.0, reward_ca=0.0, collided=False, arrived=False,
                          episode_end=False)
        return encode(msgspec.structs.replace(obs, **fields))

    for fields in ({"neighbours": [(7, 2, 2)]}, {"neighbours": [(1, 40, 2)]},
                   {"neighbours": [(1, 2, 2), (2, 3, 3), (4, 1, 2)]},
                   {"neighbours": [(1, 2, 2), (1, 3, 3)]}, {"neighbours": [(2, 3, 3), (1, 2, 2),
                                                                           (2, 1, 1)]},
                   {"neighbours": [(1, 2, 2), (0, 1, 2)]}, {"neighbours": [(1, 65535, 2)]},
                   {"position": (11, 1)}, {"goal": (5, 300)}, {"parked": [9]}, {"rank": 5}):
        if "neighbours" in fields:
            fields = {"neighbours": pack_neighbours(fields["neighbours"])}
        if "parked" in fields:
            fields = {"parked": pack_ids(fields["parked"])}
        assert kinds(protocol.on_observation(forged(**fields), 0.0)) == [], fields
    assert protocol.inbox.rejections["bad-field:neighbours"] == 11
    assert kinds(protocol.on_observation(forged(neighbours=pack_neighbours([(1, 2, 2)])[:5]),
                                         0.0)) == [], "a packing cut short: the codec's"
    assert protocol.inbox.rejections["bad-field:neighbours"] == 12
    assert protocol.decided_tick == -1
    assert "SendIntent" in kinds(protocol.on_observation(forged(), 0.0)), "the honest one decides"


def test_a_neighbour_that_is_gone_or_refuses_the_tick_is_waited_for_no_more():
    """A neighbour that is gone (no queryable: Zenoh ends the ask at once) or refuses the tick
    cost the whole negotiation time-out at every tick, as simulated histories showed."""
    others = [(0, 2, 2), (1, 1, 3)]  # agent 2, at (1, 1), could meet both; agent 1 could meet 0
    protocol = ready(agent=2)
    effects = protocol.on_observation(observation(0, agent=2, others=others), 0.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]
    assert kinds(protocol.on_ask_end(ask.ask, 0.001)) == [], "a live neighbour may answer yet"
    protocol = ready(agent=2)
    protocol.on_liveliness(keys.alive_key("proto", keys.ROLE_AGENT, 1), False, 0.0)
    effects = protocol.on_observation(observation(0, agent=2, others=others), 0.0)
    [ask] = [e for e in effects if isinstance(e, Ask)]  # agent 1 would relay agent 0's intent
    assert ask.agent == 1
    effects = protocol.on_ask_end(ask.ask, 0.001)  # its body is there, its queryable is not
    [missing] = [e for e in effects if isinstance(e, Ask)]  # so agent 0 is asked directly
    assert missing.agent == 0 and protocol.phase is Phase.ASKING_MISSING
    effects = protocol.on_refusal(missing.ask, 0.002)  # and cannot answer that tick
    assert "SendIntent" in kinds(effects) and protocol.decided_tick == 0
    assert protocol.phase is Phase.IDLE


def test_shared_table_updates_are_written_and_entries_outside_the_tables_refused():
    """Entries beyond this learner's tables are refused, and values not finite or beyond a
    reward's bounds, and a whole group whose values are not as many as its entries; the rest
    is written."""
    assert CONFIG.shared
    protocol = ready()
    [uneven] = pack_updates((8 * 5, 8 * 5 + 1), (3.0, 3.0))
    payload = encode(Observation(
        run="proto", tick=0, sender=WORLD_SENDER, agent=0, episode=0, step=0, position=(1, 1),
        goal=(5, 5), neighbours=b"", rank=0, reward_ds=0.0, reward_ca=10.0, collided=False,
        arrived=False, episode_end=False,
        updates=(pack_updates((7 * 5 + 1, 441 * 5 + 3), (20.5, -1.5))
                 + pack_updates((441 * 6 * 5,), (1.0,))
                 + ((uneven[0], uneven[1][:8]),)
                 + pack_updates((9 * 5, 9 * 5 + 1, 9 * 5 + 2, 9 * 5 + 3),
                                (math.nan, math.inf, -2e6, 7.5)))))
    assert "SendIntent" in kinds(protocol.on_observation(payload, 0.0))
    q_ds, q_ca = protocol.brain.learner.tables()
    assert q_ds[7, 1] == 20.5 and q_ca[0, 3] == -1.5 and q_ds[9, 3] == 7.5
    assert q_ds[8, 0] == q_ds[8, 1] == CONFIG.optimistic, "the uneven group is not written"
    assert (q_ds[9, :3] == CONFIG.optimistic).all(), "nor a value not finite, or out of bounds"
    assert protocol.inbox.rejections["bad-update"] == 1, "Q_CA has 882 rows here, not 2646"
    assert protocol.brain.rejected_updates == 1 + 2 + 3


def test_a_token_of_an_agent_outside_the_run_is_rejected_and_never_asked():
    """A rogue session's token alive/agent/99 once made every agent open a standing query on
    an intent key it has no agent for (and crash)."""
    protocol = ready(agent=0)
    effects = protocol.on_liveliness(keys.alive_key(CONFIG.run_id, keys.ROLE_AGENT, 99), True, 0.0)
    assert kinds(effects) == [] and protocol.inbox.rejections["unknown-agent"] == 1
    assert protocol.peers_seen == {0, 1, 2}, "not a peer to ask or to wait for"


def test_the_phases_move_only_as_the_transition_table_says():
    """Every phase but the last can stop; only a negotiation can ask for the missing intents;
    an event the table does not allow is a bug, raised, and leaves the phase as it was."""
    assert {phase for phase, _ in TRANSITIONS} == set(Phase) - {Phase.STOPPED}
    assert all(TRANSITIONS[phase, Event.STOP] is Phase.STOPPED for phase in Phase
               if phase is not Phase.STOPPED)
    assert [key for key, to in TRANSITIONS.items() if to is Phase.ASKING_MISSING] == [
        (Phase.NEGOTIATING, Event.ANSWERS_IN)]
    protocol = AgentMachine(0, CONFIG, AgentBrain(0, CONFIG), now=0.0)
    assert protocol.phase is Phase.PEERS and protocol.timer() == PEER_WAIT_S
    with pytest.raises(PhaseError, match="DECIDED in phase PEERS"):
        protocol._go(Event.DECIDED)
    assert protocol.phase is Phase.PEERS
    protocol.stop(0.0)
    assert protocol.phase is Phase.STOPPED and protocol.timer() is None
    assert protocol.on_timer(PEER_WAIT_S) == [] and protocol.stop(1.0) == []


def test_a_world_that_stays_away_longer_than_the_wait_stops_the_agent():
    protocol = ready(agent=1)
    protocol.world_wait_s = 5.0
    protocol.on_world(False, 1.0)
    protocol.on_world(True, 4.0)  # back in time (a resumed world): nothing to do
    assert protocol.timer() is None
    protocol.on_world(False, 10.0)
    assert protocol.timer() == 15.0 and protocol.on_timer(14.9) == []
    effects = protocol.on_timer(15.0)
    assert any(isinstance(e, Stopped) and not e.by_world for e in effects)
    assert protocol.world_lost and protocol.stopped and not protocol.shutdown
    assert protocol.stats()["world_lost"]
