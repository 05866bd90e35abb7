"""The world's protocol machine, pure: the lockstep clock as inputs in, effects out."""

import logging
from dataclasses import replace

import numpy as np
import pytest

from nnql_swarm.learning.tables import Learner
from nnql_swarm.learning.record import write_entries, write_updates
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.actions import DOWN, LEFT, RIGHT, STAY, UP, sees
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import Finished, Log, SendControl, SendObservations, TickClosed, WriteRow
from nnql_swarm.protocol.messages import (
    CONTROL_SHUTDOWN, Intent, agent_sender, encode, pack_updates, unpack_group, unpack_ids,
    unpack_neighbours,
)
from nnql_swarm.world.engine import QUIET_CATCH_UP, SwarmWorld
from nnql_swarm.world.world_machine import (
    LATE_LOG_EVERY, LATE_LOG_FIRST, SHUTDOWN_QUIET_S, SHUTDOWN_REPEAT_S, SHUTDOWN_TRIES,
    TRANSITIONS, Event, Phase, WorldMachine,
)
from nnql_swarm.protocol.phase_machine import PhaseError

CONFIG = SwarmConfig(run_id="wproto", n_agents=2, episodes=2, max_steps=3, tick_deadline_s=0.5)


def alive(protocol: WorldMachine, agent: int, now: float, up: bool = True) -> list:
    return protocol.on_liveliness(keys.alive_key("wproto", keys.ROLE_AGENT, agent), up, now)


def intent(protocol: WorldMachine, agent: int, now: float, action: int = 4, tick=None,
           episode: int = 0) -> list:
    tick = protocol.world.tick if tick is None else tick
    payload = encode(Intent("wproto", tick, agent_sender(agent), agent, episode, action))
    return protocol.on_intent(keys.intent_key("wproto", agent), payload, now)


def kinds(effects) -> list[str]:
    return [type(e).__name__ for e in effects if not isinstance(e, Log)]


@pytest.fixture
def believing(monkeypatch):
    """The world believes every record that fits the table: for the tests of how records are
    applied and spread, with records made up by hand (what the world checks of a record, and
    how: ``tests/test_records.py``)."""
    monkeypatch.setattr(WorldMachine, "_check_record", lambda protocol, agent, final: None)


def started(now: float = 0.0) -> tuple[WorldMachine, list]:
    protocol = WorldMachine(CONFIG, now)
    alive(protocol, 0, now)
    return protocol, alive(protocol, 1, now)


def test_the_first_tick_opens_once_every_agent_is_alive_in_rank_order():
    protocol = WorldMachine(CONFIG, 0.0)
    assert kinds(alive(protocol, 1, 0.1)) == [] and protocol.timer() == 60.0
    effects = alive(protocol, 0, 0.2)
    [batch] = [e for e in effects if isinstance(e, SendObservations)]
    sent = [obs for obs, payload in batch.observations]
    assert [o.agent for o in sent] == [0, 1] and [o.rank for o in sent] == [0, 1]
    assert protocol.timer() == 0.2 + CONFIG.tick_deadline_s


def test_an_agent_that_never_comes_alive_ends_the_start_up_with_a_reason():
    protocol = WorldMachine(CONFIG, 0.0, startup_timeout_s=5.0)
    alive(protocol, 0, 1.0)
    effects = protocol.on_timer(5.0)
    assert kinds(effects) == ["SendControl", "Finished"]
    assert effects[-1] == Finished(False, "agents [1] did not come alive within 5 s")


def test_the_last_intent_closes_the_tick_and_a_missing_one_waits_for_the_deadline():
    protocol, _ = started()
    assert kinds(intent(protocol, 0, 0.1)) == []
    effects = intent(protocol, 1, 0.2)
    assert kinds(effects) == ["SendObservations", "TickClosed"]
    assert protocol.world.tick == 1
    intent(protocol, 1, 0.3)
    assert protocol.on_timer(0.69) == [] and protocol.world.tick == 1
    effects = protocol.on_timer(0.7)
    [closed] = [e for e in effects if isinstance(e, TickClosed)]
    assert closed.report.missed == (0,)
    [late] = [e for e in effects if isinstance(e, Log) and e.level == logging.WARNING]
    assert late.message % late.args == ("tick 1 closed at its 0.5 s deadline without the "
                                        "intents of live agents [0] (1 such ticks)")
    assert protocol.stats()["late_ticks"] == 1
    intent(protocol, 0, 0.8, tick=0)
    assert protocol.inbox.rejections["stale-tick"] == 1


def test_a_dead_agent_is_not_waited_for():
    protocol, _ = started()
    intent(protocol, 0, 0.1)
    effects = alive(protocol, 1, 0.2, up=False)
    assert "TickClosed" in kinds(effects) and protocol.world.tick == 1
    assert protocol.stats()["late_ticks"] == 0, "closed by the last live agent's intent"


def test_ticks_closed_late_are_logged_the_first_few_then_every_hundredth():
    protocol = WorldMachine(replace(CONFIG, episodes=50, max_steps=10), 0.0)
    alive(protocol, 0, 0.0), alive(protocol, 1, 0.0)
    now, logged = 0.0, []
    for _ in range(LATE_LOG_EVERY + 1):
        intent(protocol, 1, now)
        now = protocol.timer()
        logged += [e for e in protocol.on_timer(now)
                   if isinstance(e, Log) and "deadline" in e.message]
    assert protocol.stats()["late_ticks"] == LATE_LOG_EVERY + 1
    assert [e.args[-1] for e in logged] == [*range(1, LATE_LOG_FIRST + 1), LATE_LOG_EVERY]


def test_a_world_every_agent_left_ends_with_a_reason_unless_one_comes_back_in_time():
    protocol = WorldMachine(replace(CONFIG, episodes=100), 0.0, startup_timeout_s=5.0)
    alive(protocol, 0, 0.0), alive(protocol, 1, 0.0)
    alive(protocol, 0, 1.0, up=False), alive(protocol, 1, 1.0, up=False)  # e.g. told to stop
    assert protocol.timer() == 1.0 + CONFIG.tick_deadline_s  # ticks at its deadline meanwhile
    alive(protocol, 1, 5.9)  # one came back: the world goes on with it
    alive(protocol, 1, 6.0, up=False)
    now = 6.0
    while protocol.timer() < 11.0:
        now = protocol.timer()
        assert "Finished" not in kinds(protocol.on_timer(now))
    assert protocol.timer() == 11.0 and protocol.world.tick > 5
    effects = protocol.on_timer(11.0)
    assert kinds(effects) == ["SendControl", "Finished"] and protocol.done
    assert effects[-1] == Finished(False, f"every agent left by tick {protocol.world.tick} and "
                                          f"none came back within 5 s: the world does not "
                                          f"play alone")


def test_an_episodes_row_follows_its_end_tick_with_the_time_it_took():
    protocol, _ = started(10.0)
    now = 10.0
    for _ in range(CONFIG.max_steps + 1):
        now += 0.25
        effects = intent(protocol, 0, now) + intent(protocol, 1, now)
    [row] = [e for e in effects if isinstance(e, WriteRow)]
    assert kinds(effects)[-2:] == ["TickClosed", "WriteRow"]
    assert row.row["episode"] == 0 and row.ticks == CONFIG.max_steps + 1
    assert row.duration_s == now - 10.0 and row.slowest_s == 0.25


def test_a_completed_run_tells_its_agents_until_they_leave():
    """A shutdown lost on the way is sent again until every live agent has left, so that no
    agent waits for ever for a world that has gone."""
    protocol, _ = started()
    now, effects = 0.0, []
    while not any(isinstance(e, SendControl) for e in effects):
        now += 0.01
        effects = intent(protocol, 0, now, episode=protocol.world.episode) + intent(
            protocol, 1, now, episode=protocol.world.episode)
    assert protocol.world.finished and protocol.phase is Phase.CLOSING
    [control] = [e for e in effects if isinstance(e, SendControl)]
    assert control.control.command == CONTROL_SHUTDOWN
    assert kinds(protocol.on_timer(now + SHUTDOWN_REPEAT_S)) == ["SendControl"]
    assert kinds(alive(protocol, 0, now + 0.3, up=False)) == []
    assert kinds(alive(protocol, 1, now + 0.4, up=False)) == []
    assert "Finished" not in kinds(protocol.on_timer(now + 0.4 + SHUTDOWN_QUIET_S / 2))
    assert protocol.on_timer(now + 0.4 + SHUTDOWN_QUIET_S)[-1] == Finished(True, None)
    assert protocol.phase is Phase.DONE and protocol.completed and protocol.timer() is None


def test_an_agent_that_comes_up_while_the_others_leave_is_told_too():
    """A stalled world that handles, all at once, the last agents leaving and a restarted one
    coming up tells the newcomer too before it ends."""
    protocol, _ = started()
    protocol.world.finished = True
    protocol._close_run(1.0)
    alive(protocol, 0, 3.0 - 0.5, up=False)
    alive(protocol, 1, 3.0 - 0.5, up=False)
    alive(protocol, 1, 3.0 - 0.5)  # restarted meanwhile
    assert kinds(protocol.on_timer(protocol.timer())) == ["SendControl"]


def test_agents_that_never_leave_are_told_a_few_times_only_however_long_it_takes():
    """A world stalled for longer than its shutdown's repeats still makes every try (tries, not
    a time limit), so that agents a partition cut off are told too."""
    protocol, _ = started()
    protocol.world.finished = True  # as if the last tick had just closed
    protocol._close_run(1.0)
    resent, now = 0, 1.0 + 10 * SHUTDOWN_REPEAT_S * SHUTDOWN_TRIES  # stalled meanwhile
    while not protocol.done:
        effects = protocol.on_timer(now)
        resent += kinds(effects).count("SendControl")
        now = protocol.timer() or now
    assert protocol.completed and resent == SHUTDOWN_TRIES - 1


def test_a_stop_tells_everyone_once_and_ends():
    protocol, _ = started()
    effects = protocol.stop(0.1)
    assert kinds(effects) == ["SendControl", "Finished"] and not protocol.completed
    assert protocol.stop(0.2) == [] and intent(protocol, 0, 0.3) == []


def test_an_intent_decided_for_an_earlier_world_is_not_taken_for_this_ones():
    """A world started again (``--resume`` under agents that kept running) is another
    incarnation: its observations name it, and an intent decided on the world before it is
    refused, counted, and the agent waited for, not taken as this world's."""
    protocol = WorldMachine(CONFIG, 0.0, incarnation=2)
    alive(protocol, 0, 0.0)
    [batch] = [e for e in alive(protocol, 1, 0.0) if isinstance(e, SendObservations)]
    assert {obs.world for obs, _ in batch.observations} == {2}
    for agent, world in ((0, 2), (1, 1)):
        payload = encode(Intent("wproto", 0, agent_sender(agent), agent, 0, STAY, world=world))
        assert kinds(protocol.on_intent(keys.intent_key("wproto", agent), payload, 0.1)) == []
    assert protocol.inbox.rejections["other-world"] == 1 and protocol.awaited == {1}
    payload = encode(Intent("wproto", 0, agent_sender(1), 1, 0, STAY, world=2))
    assert "TickClosed" in kinds(protocol.on_intent(keys.intent_key("wproto", 1), payload, 0.2))


def test_bad_intents_are_counted_never_raised():
    protocol, _ = started()
    for payload in (b"", b"\xc1", encode(Intent("wproto", 0, agent_sender(1), 1, 0, 2))):
        effects = protocol.on_intent(keys.intent_key("wproto", 0), payload, 0.1)
        assert kinds(effects) == []
    assert kinds(alive(protocol, 7, 0.1)) == [] and protocol.inbox.rejections["unknown-agent"]
    intent(protocol, 0, 0.2, episode=1)
    assert set(protocol.inbox.rejections) >= {"not-msgpack", "forged-sender", "wrong-episode"}


def test_a_world_resumed_after_the_last_episode_only_tells_the_agents_to_stop():
    """Seed 5382 of launch/faultsim.py: the world crashed while telling its agents the run was
    over, and the resumed world, finding every row written, ended without telling them."""
    protocol = WorldMachine(CONFIG, 5.0, first_episode=CONFIG.episodes, first_tick=8)
    assert protocol.timer() == 5.0
    assert kinds(protocol.on_timer(5.0)) == ["SendControl"]
    assert kinds(alive(protocol, 0, 5.01)) == []  # an agent still running, from the history
    assert kinds(protocol.on_timer(protocol.timer())) == ["SendControl"]
    alive(protocol, 0, 5.3, up=False)
    assert protocol.on_timer(protocol.timer())[-1] == Finished(True, None)
    nobody = WorldMachine(CONFIG, 0.0, first_episode=CONFIG.episodes)
    effects = nobody.on_timer(0.0) + nobody.on_timer(nobody.timer())
    assert kinds(effects) == ["SendControl", "Finished"], "with nobody left it ends at once"


def test_shared_records_are_checked_once_applied_in_the_world_and_their_changes_reach_everyone(
        believing):
    """A record that fits the table is applied by the world (Eq. 9 by hand: optimistic 25,
    alpha 0.5, gamma 0.6, reward 1: 25 + 0.5 (1 + 0.6 * 25 - 25) = 20.5) and its entry goes to
    every agent; a forged one is refused, and its intent still counts."""
    assert CONFIG.shared and CONFIG.optimistic == 25.0 and CONFIG.alpha == 0.5
    protocol, _ = started()
    tick = protocol.world.tick
    good = ((7, 1, 0, 9, 1, 0), (1.0, 0.0))  # s=7, a=1, not terminal, s'=9, no neighbour
    forged = ((500, 1, 0, 9, 1, 0), (1.0, 0.0))  # a goal state beyond the table's 441
    for agent, record in ((0, good), (1, forged)):
        payload = encode(Intent("wproto", tick, agent_sender(agent), agent, 0, 4, (record,)))
        effects = protocol.on_intent(keys.intent_key("wproto", agent), payload, 0.1)
    assert protocol.inbox.rejections["bad-record"] == 1
    [closed] = [e for e in effects if isinstance(e, TickClosed)]
    assert closed.report.missed == ()
    [batch] = [e for e in effects if isinstance(e, SendObservations)]
    assert [obs.updates for obs, _ in batch.observations] == [pack_updates((7 * 5 + 1,), (20.5,))] * 2
    q_ds, _ = protocol.world.table.tables()
    assert q_ds[7, 1] == 20.5 and (q_ds == 25.0).sum() == q_ds.size - 1


def test_the_end_ticks_row_carries_the_shared_table_as_the_agents_checkpointed_it(believing):
    """The end tick's own records are applied after the table is taken for the checkpoint."""
    protocol, _ = started()
    record = ((7, 1, 0, 9, 1, 0), (1.0, 0.0))
    for _ in range(CONFIG.max_steps + 1):
        tick = protocol.world.tick
        for agent in (0, 1):
            payload = encode(Intent("wproto", tick, agent_sender(agent), agent, 0, 4,
                                    (record,) if protocol.world.ending else ()))
            effects = protocol.on_intent(keys.intent_key("wproto", agent), payload, 0.1)
    [row] = [e for e in effects if isinstance(e, WriteRow)]
    assert (row.table[0] == 25.0).all(), "taken before the end tick's records"
    assert protocol.world.table.tables()[0][7, 1] != 25.0, "which the world then applied"


def test_an_agent_that_comes_back_is_sent_the_whole_table_until_its_copy_is_the_worlds(
        believing):
    """Agent 1 leaves and comes back with a stale copy (all 25: what it started with); the world
    sends it the table, a slice an observation, while both agents go on learning; once the last
    slice is written its copy equals the world's. Agent 0, which never left, gets no slice."""
    config = SwarmConfig(run_id="wproto", n_agents=2, episodes=4, max_steps=40,
                         tick_deadline_s=0.5)
    protocol = WorldMachine(config, 0.0)
    alive(protocol, 0, 0.0)
    effects = alive(protocol, 1, 0.0)
    stale = Learner(config)
    entries = protocol.world.table.entries
    records = [((s, s % 5, 0, (s + 1) % 441, 1, 0), (1.0, 0.0)) for s in range(300)]

    def tick(number: int) -> list:
        t = protocol.world.tick
        out = []
        for agent in (0, 1):
            record = () if protocol.world.ending else (records[(2 * number + agent) % 300],)
            payload = encode(Intent("wproto", t, agent_sender(agent), agent,
                                    protocol.world.episode, 4, record))
            out += protocol.on_intent(keys.intent_key("wproto", agent), payload, 0.1)
        return out

    for number in range(5):
        effects = tick(number)
    alive(protocol, 1, 0.2, up=False)
    alive(protocol, 1, 0.3)
    assert protocol.world.syncing == (), "not before it shows it hears the observations"
    [batch] = [e for e in effects if isinstance(e, SendObservations)]
    write_updates(stale.entries, dict((obs.agent, obs) for obs, _ in batch.observations)[1].updates,
                  write_entries)
    effects = tick(5)
    assert protocol.world.syncing == (1,)
    slices = 0
    for number in range(6, 6 + 12):
        [batch] = [e for e in effects if isinstance(e, SendObservations)]
        observed = {obs.agent: obs for obs, _ in batch.observations}
        assert len(observed[0].updates) <= 1, "the agent that stayed gets the tick's group only"
        slices += len(observed[1].updates) > 1
        write_updates(stale.entries, observed[1].updates, write_entries)
        effects = tick(number)
    assert slices == -(-entries // 2048) and protocol.world.syncing == ()
    [batch] = [e for e in effects if isinstance(e, SendObservations)]
    write_updates(stale.entries, dict((obs.agent, obs) for obs, _ in batch.observations)[1].updates,
                  write_entries)
    world_q_ds, world_q_ca = protocol.world.table.tables()
    q_ds, q_ca = stale.tables()
    assert (world_q_ds != 25.0).sum() > 10, "the world learned meanwhile"
    assert np.array_equal(q_ds, world_q_ds) and np.array_equal(q_ca, world_q_ca)


def test_a_record_the_world_saw_no_decision_for_is_refused_and_its_intent_counts():
    """At a run's first tick nobody has decided yet: a record then is none the agent's own
    transition wrote (``world.records``)."""
    protocol, _ = started()
    record = ((7, 1, 0, 9, 1, 0), (1.0, 0.0))
    for agent in (0, 1):
        payload = encode(Intent("wproto", 0, agent_sender(agent), agent, 0, RIGHT, (record,)))
        effects = protocol.on_intent(keys.intent_key("wproto", agent), payload, 0.1)
    assert protocol.inbox.rejections["unchecked-record"] == 2
    [closed] = [e for e in effects if isinstance(e, TickClosed)]
    assert closed.report.actions == (RIGHT, RIGHT) and closed.report.records == {}
    assert (protocol.world.table.tables()[0] == 25.0).all()


def test_a_resumed_world_sends_every_agent_the_whole_table():
    protocol = WorldMachine(CONFIG, 0.0, first_episode=1, first_tick=4)
    alive(protocol, 0, 0.0)
    alive(protocol, 1, 0.0)
    intent(protocol, 0, 0.1, episode=1)
    assert protocol.world.syncing == (0,)
    intent(protocol, 1, 0.1, episode=1)
    assert protocol.world.syncing == (0, 1)


def toward_goal(obs) -> int:
    """The move that brings an agent one cell nearer its goal (STAY there)."""
    (x, y), (gx, gy) = obs.position, obs.goal
    if gx != x:
        return RIGHT if gx > x else LEFT
    if gy != y:
        return DOWN if gy > y else UP
    return STAY


@pytest.mark.parametrize("wait_rule", ["reach", "meet"])
def test_under_meet_a_settled_agent_is_neither_waited_for_nor_sent_observations(wait_rule):
    """Agent 0 walks to its goal while agent 1 stays. Under ``meet``, from the tick after agent
    0's first arrived observation it is settled: the world needs no intent from it, so agent 1's
    alone closes the tick and nobody missed one, and it is sent no observation until the end
    tick (its few missed table entries come then); an intent of agent 0 for a tick already
    closed is stale, as any late one. Under ``reach`` a parked agent still relays down the
    chain: it never settles, and every tick waits for it."""
    config = SwarmConfig(run_id="wproto", n_agents=2, episodes=1, max_steps=40,
                         tick_deadline_s=0.5, wait_rule=wait_rule)
    protocol = WorldMachine(config, 0.0)
    alive(protocol, 0, 0.0)
    effects, now, seen = alive(protocol, 1, 0.0), 0.0, []
    while not protocol.world.finished:
        settled = 0 in protocol.world.settled
        [batch] = [e for e in effects if isinstance(e, SendObservations)]
        obs = {o.agent: o for o, _ in batch.observations}
        mine = obs.get(0)
        seen.append((settled, mine is not None and mine.arrived))
        assert obs[1].settled is False
        if settled:
            assert mine is None, "a settled agent hears nothing"
        else:
            assert mine is not None and not mine.settled
        now += 0.01
        effects = intent(protocol, 1, now, action=STAY)
        if settled:
            assert "TickClosed" in kinds(effects), "agent 1 alone closes a settled agent's tick"
            [closed] = [e for e in effects if isinstance(e, TickClosed)]
            assert closed.report.missed == ()
            if sum(s for s, _ in seen) == 1:  # the first settled tick: one late intent
                assert kinds(intent(protocol, 0, now, tick=closed.report.tick)) == []
                assert protocol.inbox.rejections["stale-tick"] == 1
        else:
            assert "TickClosed" not in kinds(effects), "a moving agent is waited for"
            effects += intent(protocol, 0, now, action=toward_goal(mine))
    arrived_at = [a for _, a in seen].index(True)
    if wait_rule == "reach":
        assert not any(s for s, _ in seen) and len(seen) == config.max_steps + 1
    else:
        assert [s for s, _ in seen] == [False] * (arrived_at + 1) + [True] * (
            len(seen) - arrived_at - 2) + [False], "settled from the tick after, never at the end"
    assert protocol.inbox.rejections.get("duplicate-intent") is None


def test_an_intent_of_a_settled_agent_is_taken_once_and_moves_nothing():
    """A settled agent sends an intent only to deliver a learning record: it is taken, its
    action stays STAY, and a second one for the tick is a duplicate."""
    protocol, _ = started()
    protocol.world.settled = frozenset({0})  # as the engine has it after agent 0 arrived
    protocol._out = []
    protocol._open_tick(1.0)
    assert protocol.awaited == {1} and protocol.intents.tolist() == [STAY, -1]
    assert kinds(intent(protocol, 0, 1.1, action=UP)) == [] and protocol.intents[0] == STAY
    intent(protocol, 0, 1.2)
    assert protocol.inbox.rejections["duplicate-intent"] == 1
    assert "TickClosed" in kinds(intent(protocol, 1, 1.3))


def test_a_settled_agent_that_came_back_is_waited_for_to_be_sent_the_table():
    """A restarted agent is sent the world's table from its first intent on, so the world waits
    for its intent even once it has arrived: its observation does not say settled."""
    protocol, _ = started()
    protocol.world.settled = frozenset({0, 1})
    protocol.to_resync.add(1)
    protocol._out = []
    protocol._open_tick(1.0)
    [batch] = [e for e in protocol._out if isinstance(e, SendObservations)]
    assert CONFIG.quiet_settled  # agent 0, settled, is quiet: it gets no observation
    assert {o.agent: o.settled for o, _ in batch.observations} == {1: False}
    assert protocol.awaited == {1} and protocol.intents.tolist() == [STAY, -1]


def test_a_quiet_agent_hears_the_table_entries_it_missed_at_its_next_observation():
    """Under ``meet`` a settled agent gets no observation; the world keeps the shared table's
    entries it did not hear of, and its next one (once QUIET_CATCH_UP of them wait, or at the
    end tick) brings each of them with its current value, so its copy is the world's again."""
    config = SwarmConfig(run_id="wproto", n_agents=2, episodes=1, max_steps=40)
    assert config.quiet_settled and config.shared
    world = SwarmWorld(config)
    world.settled = frozenset({0})
    entries = world.table._learner.entries
    sent_to_0, written = [], {}
    for tick in range(QUIET_CATCH_UP):
        changed = [(7 * tick) % len(entries), (7 * tick + 3) % len(entries)]
        for e in changed:
            entries[e] = float(tick)
            written[e] = float(tick)
        world._updates = world.table.current(changed)  # as a tick's records leave them
        observed = {o.agent: o for o in world.observations_by_rank()}
        assert 1 in observed, "a moving agent hears every tick"
        if 0 in observed:
            sent_to_0.append((tick, observed[0]))
            break
    [(tick, obs)] = sent_to_0
    assert len(written) == QUIET_CATCH_UP == 2 * (tick + 1) and obs.settled
    heard = {}
    for group in obs.updates:
        indices, values = unpack_group(group)
        heard.update(zip(indices.tolist(), values.tolist()))
    assert heard == written, "every missed entry, with its value now"
    world.settled = frozenset()  # the end tick: it is sent its observation as everyone
    world._updates = ()
    assert {o.agent for o in world.observations_by_rank()} == {0, 1}


def test_an_agent_being_resynchronised_is_never_quiet():
    config = SwarmConfig(run_id="wproto", n_agents=2, episodes=1, max_steps=40)
    world = SwarmWorld(config)
    world.settled = frozenset({0})
    world.resync(0)
    world._sync_from_next.clear()
    [obs_0] = [o for o in world.observations_by_rank() if o.agent == 0]
    assert obs_0.settled and obs_0.updates, "its slice of the table goes with it"


def test_the_phases_move_only_as_the_transition_table_says():
    """Start, tick after tick, close, done: every phase but the last can end, only a start or a
    closed tick opens one, and an event the table does not allow is a bug, raised."""
    assert {phase for phase, _ in TRANSITIONS} == set(Phase) - {Phase.DONE}
    assert [key for key, to in TRANSITIONS.items() if to is Phase.TICK_OPEN] == [
        (Phase.STARTING, Event.STARTED), (Phase.TICK_OPEN, Event.TICK_CLOSED)]
    protocol = WorldMachine(CONFIG, now=0.0)
    assert protocol.phase is Phase.STARTING
    with pytest.raises(PhaseError, match="TICK_CLOSED in phase STARTING"):
        protocol._go(Event.TICK_CLOSED)
    alive(protocol, 0, 0.1)
    alive(protocol, 1, 0.1)
    assert protocol.phase is Phase.TICK_OPEN and protocol.timer() == 0.1 + CONFIG.tick_deadline_s
    assert kinds(protocol.stop(0.2))[-1] == "Finished" and protocol.phase is Phase.DONE
    assert protocol.on_timer(9.0) == [] and protocol.stop(9.0) == [] and protocol.timer() is None
    finished = WorldMachine(CONFIG, now=0.0, first_episode=CONFIG.episodes)
    assert finished.phase is Phase.CLOSING  # resumed after the last row: only the goodbyes


@pytest.mark.parametrize("on_target", ["park", "step-aside"])
def test_every_observation_lists_whom_its_agent_sees_in_id_order_and_the_parked_among_them(
        on_target):
    """``SwarmWorld`` packs every agent's neighbours for the tick at once
    (``world.sight.pack_seen``); each observation's are those its agent sees (``protocol.actions.sees``, pair by pair), in id order, with the
    arrived ones among them parked where arrived agents park."""
    rng = np.random.default_rng(7)
    for n, side in ((2, 4), (8, 11), (16, 16), (64, 32), (64, 40)):
        world = SwarmWorld(SwarmConfig(n_agents=n, width=side, height=side, seed=1,
                                       on_target=on_target))
        for _ in range(5):
            cells = rng.choice(side * side, n, replace=False)
            xs, ys = (cells % side).tolist(), (cells // side).tolist()
            world._x[:n], world._y[:n] = xs, ys
            arrived = (rng.random(n) < 0.3).tolist()
            world._arrived[:n] = arrived
            world._plain()  # as a tick's step leaves it
            for obs in world.observations():
                i = obs.agent
                near = [j for j in range(n) if j != i and sees(xs[i], ys[i], xs[j], ys[j])]
                assert unpack_neighbours(obs.neighbours).tolist() == [
                    [j, xs[j], ys[j]] for j in near]
                assert unpack_ids(obs.parked).tolist() == (
                    [] if on_target == "step-aside" else [j for j in near if arrived[j]])
