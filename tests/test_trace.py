"""Tick traces (protocol.trace, bench/tick_trace.py): off by default, and lined up tick by tick."""

import json

from bench.harness import run_distributed
from bench.tick_trace import (
    ANSWER_IN, FIRST_OBS, HOP, LAST_INTENT, LEARNING, NEXT_OBS, TICK, by_tick, read_trace,
    tick_steps,
)
from nnql_swarm.protocol import trace
from nnql_swarm.protocol.config import PRESETS, SwarmConfig


def test_a_trace_is_off_unless_it_has_a_directory(tmp_path):
    off = trace.TickTrace("agent-0", None)
    off.mark(trace.DECIDE, 3)
    off.save()
    assert off.marks == [] and off.now() == 0.0
    on = trace.TickTrace("agent-0", tmp_path / "marks")
    on.mark(trace.DECIDE, 3, at=1.5)
    on.mark(trace.ACTED, 3)
    on.save()
    saved = json.loads((tmp_path / "marks" / "agent-0.json").read_text())
    assert saved[0] == [trace.DECIDE, 3, 1.5] and saved[1][:2] == [trace.ACTED, 3]


def test_the_steps_of_a_tick_are_lined_up_sender_by_sender():
    # Three agents; at tick 3 agent 0 ranks first ((0 - 3) mod 3 == 0), then 1, then 2. Agent 2
    # waits for agent 0 (not for the rank just above it); agent 1's intent is the tick's last.
    world = {3: {trace.OBS_SENT: 0.0, trace.CLOSE: 12.0}, 4: {trace.OBS_SENT: 13.0}}
    first = {trace.OBS_IN: 1.0, trace.DECIDE: 1.5, trace.ACTED: 2.0, trace.ENCODED: 2.5,
             trace.ANSWERED: 3.0, trace.INTENT_SENT: 3.5}
    second = {trace.OBS_IN: 1.1, trace.DECIDE: 1.6, trace.ACTED: 2.1, trace.ENCODED: 2.6,
              trace.ANSWERED: 2.7, trace.INTENT_SENT: 9.0}
    third = {trace.OBS_IN: 1.2, trace.ANSWER_IN: {0: 4.0}, trace.DECIDE: 4.5,
             trace.ACTED: 6.0, trace.ENCODED: 6.5, trace.ANSWERED: 7.0, trace.INTENT_SENT: 8.0}
    agents = {0: {3: first}, 1: {3: second}, 2: {3: third}}
    steps = tick_steps(world, agents, [3])
    assert steps[FIRST_OBS] == [1.0]
    assert steps[LEARNING] == [0.5, 0.5, 1.5]
    assert steps[HOP] == [1.5], "agent 0 encoded its answer at 2.5, agent 2 had it at 4.0"
    assert steps[ANSWER_IN] == [0.5], "only agent 2 waited"
    assert steps[LAST_INTENT] == [3.0], "from agent 1's intent at 9.0, not the last rank's"
    assert steps[NEXT_OBS] == [1.0] and steps[TICK] == [13.0]
    partial = {3: {trace.OBS_IN: 1.1, trace.DECIDE: 1.6}}
    incomplete = tick_steps(world, {**agents, 1: partial}, [3])
    assert incomplete[TICK] == [], "incomplete ticks are left out"
    quiet = tick_steps(world, {**agents, 1: {}}, [3])  # sent no observation: a quiet agent
    assert quiet[TICK] == [13.0] and quiet[LEARNING] == [0.5, 1.5]
    assert quiet[LAST_INTENT] == [4.0], "agent 2's intent, at 8.0, is then the last"


def test_marks_name_their_peer_where_given(tmp_path):
    on = trace.TickTrace("agent-2", tmp_path)
    on.mark(trace.ANSWER_IN, 3, at=4.0, peer=0)
    on.mark(trace.DECIDE, 3, at=4.5)
    on.save()
    assert by_tick(json.loads((tmp_path / "agent-2.json").read_text())) == {
        3: {trace.ANSWER_IN: {0: 4.0}, trace.DECIDE: 4.5}}


def test_a_traced_swarm_marks_every_step_of_every_tick(tmp_path, monkeypatch):
    monkeypatch.setenv(trace.TRACE_ENV, str(tmp_path / "marks"))
    config = SwarmConfig(run_id="traced", n_agents=3, episodes=2, max_steps=15,
                         **PRESETS["nnql"])  # everyone in reach: a chain of answers
    run_distributed(config, tmp_path / "run", record=False)
    world, agents = read_trace(tmp_path / "marks", 3)
    steps = tick_steps(world, agents, sorted(world))
    assert len(steps[TICK]) >= 20, "almost every tick of the run is complete"
    assert len(steps[HOP]) >= 2 * 20 - 5, "every agent below the first got an answer"
    assert all(value > 0 for values in steps.values() for value in values)
