"""The world's check of learning records (``world.records``): every honest record of simulated
runs is accepted, whatever the faults; a record altered in any field is refused; a forging agent's
records are refused, and it is barred until it restarts, then checked again; the shared table
then equals the one of a run in which its records were never sent."""

from dataclasses import replace

import msgspec
import pytest

from nnql_swarm.learning.fields import (
    REC_ACTION, REC_BLOCKS, REC_COUNT, REC_GOAL, REC_NEXT_GOAL, REC_PAIRS, REC_TERMINAL,
)
from nnql_swarm.learning.planner import Planner
from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES, VIEW_RADIUS, WINDOW, offset_state
from nnql_swarm.protocol.config import PRESETS
from nnql_swarm.protocol.messages import encode
from nnql_swarm.sim.distributed import SimSwarm, run_schedule
from nnql_swarm.sim.schedule import FORGE, Fault, draw_schedule
from nnql_swarm.world.records import BARRED, FORGED, UNCHECKED, RecordCheck


def shared_schedule(seed: int, preset: str, faults=(), **options):
    """Schedule ``seed``'s run, with ``preset`` (sharing one table), ``options`` and ``faults``."""
    schedule = draw_schedule(seed)
    config = replace(schedule.config, **{**PRESETS[preset], "shared": True, **options})
    return replace(schedule, config=config, faults=tuple(faults))


class Spy:
    """Every record check of a run: its arguments and verdict."""

    def __init__(self, monkeypatch) -> None:
        self.calls = []
        honest = RecordCheck.could_write
        spy = self

        def could_write(check, record, decision, obs, intents):
            verdict = honest(check, record, decision, obs, intents)
            spy.calls.append((check, record, decision, obs, intents, verdict))
            return verdict

        monkeypatch.setattr(RecordCheck, "could_write", could_write)


class Rejections:
    """The record rejections of every world of a run."""

    def __init__(self, monkeypatch) -> None:
        self.counts = {FORGED: 0, BARRED: 0, UNCHECKED: 0}
        self.forgers = set()
        check = SimSwarm._check_world
        counts = self

        def check_world(sim):
            for reason in counts.counts:
                counts.counts[reason] += sim.world_protocol.inbox.rejections[reason]
            counts.forgers.update(sim.world_protocol.stats()["forgers"])
            check(sim)

        monkeypatch.setattr(SimSwarm, "_check_world", check_world)


@pytest.mark.parametrize("preset", ["shield-nnql", "nnql", "daql", "ql", "path-nnql"])
def test_every_honest_record_of_a_run_without_faults_is_accepted(monkeypatch, preset):
    spy, rejections = Spy(monkeypatch), Rejections(monkeypatch)
    for seed in (1, 2, 5):
        outcome = run_schedule(shared_schedule(seed, preset))
        assert outcome.failures == []
    assert len(spy.calls) > 50
    assert all(verdict for *_, verdict in spy.calls)
    assert rejections.counts == {FORGED: 0, BARRED: 0, UNCHECKED: 0}


def test_every_honest_record_under_faults_is_accepted_or_unchecked(monkeypatch, tmp_path):
    spy, rejections = Spy(monkeypatch), Rejections(monkeypatch)
    ran = 0
    for seed in range(60):
        schedule = draw_schedule(seed)
        if not schedule.config.shared or any(f.kind == FORGE for f in schedule.faults):
            continue
        ran += 1
        assert run_schedule(schedule, tmp_path).failures == []
    assert ran > 20 and len(spy.calls) > 200
    assert all(verdict for *_, verdict in spy.calls)
    assert rejections.counts[FORGED] == rejections.counts[BARRED] == 0
    assert rejections.forgers == set()


def elsewhere(row: int) -> int:
    """A Q_CA row in the same block three cells away from ``row``'s, along both axes: never a
    reading of the same neighbour (its cell, or a cell next to it it may have announced, all
    within two cells of each other)."""
    state, block = row % N_STATES, row // N_STATES
    dx, dy = state // WINDOW - VIEW_RADIUS, state % WINDOW - VIEW_RADIUS
    return offset_state(dx + (3 if dx <= 0 else -3), dy + (3 if dy <= 0 else -3)) + N_STATES * block


def alterations(record):
    """``record`` altered in each of its fields, one at a time, by name."""
    integers, (r_ds, r_ca) = record
    integers = list(integers)

    def changed(at, value):
        altered = list(integers)
        altered[at] = value
        return tuple(altered), (r_ds, r_ca)

    yield "goal", changed(REC_GOAL, (integers[REC_GOAL] + 1) % N_STATES)
    yield "action", changed(REC_ACTION, (integers[REC_ACTION] + 1) % N_ACTIONS)
    yield "terminal", changed(REC_TERMINAL, 1 - integers[REC_TERMINAL])
    yield "next goal", changed(REC_NEXT_GOAL, (integers[REC_NEXT_GOAL] + 1) % N_STATES)
    yield "blocks", changed(REC_BLOCKS, N_ACTIONS if integers[REC_BLOCKS] == 1 else 1)
    yield "reward ds", (tuple(integers), (r_ds + 0.5, r_ca))
    yield "reward ca", (tuple(integers), (r_ds, 10.0 - r_ca))
    count = integers[REC_COUNT]
    yield "one more pair", (tuple(integers[:REC_COUNT]) + (count + 1,) + tuple(integers[REC_PAIRS:])
                            + (integers[REC_GOAL], -1), (r_ds, r_ca))
    for k in range(count):
        row, following = integers[REC_PAIRS + 2 * k], integers[REC_PAIRS + 2 * k + 1]
        yield f"pair {k} s", changed(REC_PAIRS + 2 * k, elsewhere(row))
        yield f"pair {k} s'", changed(REC_PAIRS + 2 * k + 1,
                                      row % N_STATES if following < 0 else elsewhere(following))
        fewer = integers[:REC_COUNT] + [count - 1] + integers[REC_PAIRS:REC_PAIRS + 2 * k] \
            + integers[REC_PAIRS + 2 * k + 2:]
        yield f"pair {k} left out", (tuple(fewer), (r_ds, r_ca))


MAP_FIELDS = {"goal", "next goal", "reward ds"}
"""What a learner that reads its known map (``path-nnql``) alone knows: taken as sent."""


@pytest.mark.parametrize("preset", ["shield-nnql", "nnql", "daql", "ql", "path-nnql"])
def test_a_record_altered_in_any_field_is_refused(monkeypatch, preset):
    """Each honest record of two runs, altered in each field in turn, checked as the world
    checks it: at the same moment, with the plans of the ticks it reads."""
    honest_check = RecordCheck.could_write
    checked, pairs = [], [0]

    def could_write(check, record, decision, obs, intents):
        verdict = honest_check(check, record, decision, obs, intents)
        if verdict:
            checked.append(record)
            pairs[0] += record[0][REC_COUNT]
            for name, altered in alterations(record):
                if preset == "path-nnql" and name in MAP_FIELDS:
                    continue
                assert not honest_check(check, altered, decision, obs, intents), (name, record)
        return verdict

    monkeypatch.setattr(RecordCheck, "could_write", could_write)
    run_schedule(shared_schedule(2, preset))
    run_schedule(shared_schedule(7, preset))
    assert len(checked) > 50
    assert pairs[0] > 0


def forging(agent: int, tick: int):
    return Fault(FORGE, tick, 0.0, 0.0, target=f"agent-{agent}")


def test_a_forger_is_refused_barred_until_it_restarts_and_checked_again(monkeypatch, tmp_path):
    rejections, spy = Rejections(monkeypatch), Spy(monkeypatch)
    crash = Fault("crash", 5, 0.0001, 0.0005, target="agent-3")
    schedule = shared_schedule(11, "shield-nnql", [forging(3, 1), crash])
    schedule = replace(schedule, config=replace(schedule.config, episodes=3, max_steps=4))
    outcome = run_schedule(schedule, tmp_path)
    assert outcome.failures == [] and set(outcome.fired) == {FORGE, "crash"}
    assert rejections.counts[FORGED] == 1 and rejections.counts[BARRED] >= 1
    assert rejections.forgers == {3}
    restarted = [call for call in spy.calls if call[3].agent == 3 and call[3].tick > 6]
    assert restarted and all(call[-1] for call in restarted), "its new process is believed"


@pytest.mark.parametrize("seed", [3, 4])
def test_the_shared_table_is_the_one_of_a_run_without_the_forgers_records(monkeypatch, seed):
    """A forger's records refused leave the table as if it had sent none from then on."""
    schedule = shared_schedule(seed, "shield-nnql", [forging(5, 2)])
    schedule = replace(schedule, config=replace(schedule.config, episodes=3, max_steps=4))
    forged = SimSwarm(schedule)
    outcome = forged.run()
    assert outcome.failures == []
    assert forged.world_protocol.stats()["forgers"] == [5]

    _without_records_when_forging(monkeypatch)
    mute = SimSwarm(schedule)
    quiet = mute.run()
    assert quiet.rows == outcome.rows
    assert [t.tolist() for t in forged.world_protocol.world.table.tables()] == \
        [t.tolist() for t in mute.world_protocol.world.table.tables()]
    assert mute.world_protocol.stats()["rejected"] == {}


def _without_records_when_forging(monkeypatch) -> None:
    """The ``forge`` fault, made to send intents without records instead of forged ones."""
    original = SimSwarm._agent_effects

    def effects(sim, i, out):
        a = sim.agents[i]
        if sim.forging.get(i) == a.incarnation:
            for k, effect in enumerate(out):
                intent = getattr(effect, "intent", None)
                if intent is not None and intent.record:
                    intent = msgspec.structs.replace(intent, record=())
                    out[k] = effect._replace(intent=intent, payload=encode(intent))
        original(sim, i, out)

    monkeypatch.setattr(SimSwarm, "_agent_effects", effects)


@pytest.mark.parametrize("preset, options", [
    ("nnql", {}), ("path-nnql", {}), ("daql", {}), ("shield-nnql", {}),
    ("pibt-nnql", {"on_target": "step-aside", "tasks": "lifelong"}),
])
def test_the_plans_the_world_works_out_for_a_tick_are_each_observations_own(monkeypatch, preset,
                                                                             options):
    """The world reads every agent's plan of a tick at once, from the cells and arrivals of all
    (``RecordCheck.plan_tick``): for every observation of runs with faults, the neighbours and
    parked ids it reads, whom the agent waits for and whom it knows to stay are those the
    agent's own planner works out of the observation."""
    seen = []
    tick_plan = RecordCheck._negotiated
    planners = {}

    def negotiated(check, obs):
        from_tick = tick_plan(check, obs)
        planner = planners.setdefault(id(check), Planner(check.config))
        own = planner(obs)
        assert own is not None
        cells = [list(cell) for cell in own.cells]
        assert [part.tolist() for part in from_tick] == [own.awaited, own.staying, cells,
                                                          list(own.parked)]
        seen.append((obs.agent, len(from_tick[3])))
        return from_tick

    monkeypatch.setattr(RecordCheck, "_negotiated", negotiated)
    for seed in (3, 4, 7):
        run_schedule(shared_schedule(seed, preset, draw_schedule(seed).faults, episodes=3,
                                     max_steps=30, **options))  # long enough to arrive
    assert len(seen) > 100 and len({agent for agent, _ in seen}) > 2
    assert any(parked for _, parked in seen) == ("on_target" not in options)  # some park
