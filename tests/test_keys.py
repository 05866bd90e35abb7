"""Keys: the key builders, run and agent ids, intent and standing query parameters, parsed from
strings and from Zenoh's own types, and an intent query over a real Zenoh session."""

import numpy as np
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nnql_swarm.protocol import keys
from nnql_swarm.protocol.keys import MAX_AGENTS, MAX_TICK
from nnql_swarm.protocol.inbox import Inbox
from nnql_swarm.protocol.messages import Intent, agent_sender, encode

RUN = "run-1"
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def intent(**change) -> Intent:
    base = dict(run=RUN, tick=7, sender=agent_sender(2), agent=2, episode=1, action=3)
    return Intent(**{**base, **change})


def test_key_builders():
    assert keys.PREFIX == "nnql"
    assert keys.obs_key(RUN, 3) == "nnql/run-1/world/obs/3"
    assert keys.intent_key(RUN, 3) == "nnql/run-1/agent/3/intent"
    assert keys.intent_key(RUN, np.int64(3)) == "nnql/run-1/agent/3/intent"
    assert keys.intent_key_all(RUN) == "nnql/run-1/agent/*/intent"
    assert keys.control_key(RUN) == "nnql/run-1/world/control"
    assert keys.alive_key(RUN, keys.ROLE_AGENT, 5) == "nnql/run-1/alive/agent/5"
    assert keys.alive_key(RUN, keys.ROLE_WORLD, "main") == "nnql/run-1/alive/world/main"
    assert keys.alive_key_all(RUN, keys.ROLE_AGENT) == "nnql/run-1/alive/agent/*"
    everyone = zenoh.KeyExpr(keys.intent_key_all(RUN))
    assert everyone.intersects(zenoh.KeyExpr(keys.intent_key(RUN, 9)))


@pytest.mark.parametrize("bad", ["", "a/b", "*", "**", "a b", "x" * 65, "é", "$*", None, 3])
def test_invalid_run_ids(bad):
    with pytest.raises(ValueError, match="run id"):
        keys.validate_run_id(bad)
    with pytest.raises(ValueError):
        keys.obs_key(bad, 0)


def test_invalid_agent_ids_and_roles():
    for bad in (-1, MAX_AGENTS, True, 1.0, "3", None):
        with pytest.raises(ValueError):
            keys.intent_key(RUN, bad)
        with pytest.raises(ValueError):
            keys.alive_key(RUN, keys.ROLE_AGENT, bad)
    with pytest.raises(ValueError):
        keys.alive_key(RUN, "robot", 1)
    with pytest.raises(ValueError):
        keys.alive_key(RUN, keys.ROLE_WORLD, "a/b")
    with pytest.raises(ValueError):
        keys.alive_key_all(RUN, "robot")
    assert keys.validate_run_id("A_b-9") == "A_b-9"


def test_agent_from_key():
    assert keys.agent_from_key(keys.intent_key(RUN, 0), RUN) == 0
    assert keys.agent_from_key(keys.intent_key(RUN, 1023), RUN) == 1023
    assert keys.agent_from_key(keys.alive_key(RUN, keys.ROLE_AGENT, 7), RUN) == 7
    assert keys.agent_from_key(zenoh.KeyExpr(keys.intent_key(RUN, 4)), RUN) == 4
    for bad in (
        keys.intent_key("other", 4), keys.alive_key(RUN, keys.ROLE_WORLD, 4), keys.obs_key(RUN, 4),
        "nnql/run-1/agent/04/intent", "nnql/run-1/agent/1024/intent", "nnql/run-1/agent/-1/intent",
        "nnql/run-1/agent/*/intent", "nnql/run-1/agent/3/intent/x", "nnql/run-1/agent//intent",
        "nnql/run-1/agent/３/intent", "xnql/run-1/agent/3/intent", "", None, 17,
    ):
        assert keys.agent_from_key(bad, RUN) is None, bad


def test_intent_query_params_and_parse():
    assert keys.INTENT_QUERY_TICK == "tick"
    assert keys.intent_query_params(12) == "tick=12"
    assert keys.parse_intent_query("tick=12") == 12
    assert keys.parse_intent_query("?a=b;tick=0") == 0
    assert keys.parse_intent_query({"tick": "5"}) == 5
    assert keys.parse_intent_query({"tick": 5}) == 5
    assert keys.parse_intent_query(f"tick={MAX_TICK - 1}") == MAX_TICK - 1
    for bad in (
        None, "", "tick", "tick=", "tick=-1", "tick=+1", "tick=1.0", "tick=1e3", "tick= 1",
        "tick=abc", "tick=1|2", f"tick={MAX_TICK}", "tick=" + "9" * 40, "tock=3", {"tick": True},
        {"tick": -1}, {"tick": 1.0}, {}, 12, object(), "tick=٣",
    ):
        assert keys.parse_intent_query(bad) is None, bad
    for bad in (-1, MAX_TICK, True, 1.5):
        with pytest.raises((ValueError, TypeError)):
            keys.intent_query_params(bad)


def test_parse_intent_query_zenoh_parameters():
    assert keys.parse_intent_query(zenoh.Parameters(keys.intent_query_params(42))) == 42
    assert keys.parse_intent_query(zenoh.Parameters({"tick": "8"})) == 8
    selector = zenoh.Selector("nnql/r/agent/1/intent?x=1;tick=3")
    assert keys.parse_intent_query(selector.parameters) == 3
    for bad in ("", "tick=1|2", "tick=-4", "other=1", "tick=" + "1" * 30):
        assert keys.parse_intent_query(zenoh.Parameters(bad)) is None


@given(st.integers(0, MAX_TICK - 1))
@FUZZ
def test_intent_query_round_trip(tick):
    assert keys.parse_intent_query(keys.intent_query_params(tick)) == tick
    assert keys.parse_intent_query(zenoh.Parameters(keys.intent_query_params(tick))) == tick


@given(st.text(max_size=40)
       | st.dictionaries(st.text(max_size=5), st.text(max_size=5) | st.integers()))
@FUZZ
def test_parse_intent_query_never_raises(parameters):
    tick = keys.parse_intent_query(parameters)
    assert tick is None or 0 <= tick < MAX_TICK


def test_intent_query_over_a_real_zenoh_session():
    """A queryable answers ``?tick=T`` with the encoded intent; the getter decodes the ZBytes."""
    conf = zenoh.Config()
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("listen/endpoints", "[]")
    seen = []

    def answer(query):
        tick = keys.parse_intent_query(query.parameters)
        agent = keys.agent_from_key(query.key_expr, RUN)
        seen.append((tick, agent))
        reply = intent(tick=tick, agent=agent, sender=agent_sender(agent))
        query.reply(query.key_expr, encode(reply))

    inbox = Inbox(RUN)
    with zenoh.open(conf) as session:
        with session.declare_queryable(keys.intent_key(RUN, 4), answer):
            selector = f"{keys.intent_key(RUN, 4)}?{keys.intent_query_params(21)}"
            replies = [r for r in session.get(selector, timeout=5.0)]
    assert seen == [(21, 4)]
    assert replies and replies[0].ok is not None
    sample = replies[0].ok
    got = inbox.decode(sample.payload, Intent, keys.agent_from_key(sample.key_expr, RUN))
    assert got == intent(tick=21, agent=4, sender=agent_sender(4))


def test_standing_query_params():
    params = keys.standing_query_params(12, 3)
    assert params == "since=12;from=3"
    assert keys.parse_standing_since(params) == 12
    assert keys.parse_intent_asker(params) == 3
    assert keys.parse_intent_query(params) is None
    assert keys.parse_standing_since(zenoh.Parameters(params)) == 12
    assert keys.parse_intent_asker(zenoh.Parameters(keys.intent_query_params(5, 7))) == 7
    for bad in ("since=-1;from=3", "since=x", "from=01", f"from={keys.MAX_AGENTS}", None, 5):
        assert keys.parse_standing_since(bad) is None or keys.parse_intent_asker(bad) is None
