"""Wire messages and their codec: round trips, every rejection reason, the one codec path against
an independent reading of the rules, and fuzzing."""

import logging
import math
from typing import get_type_hints

import msgpack
import msgspec
import numpy as np
import pytest
import zenoh
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from nnql_swarm.protocol import keys, messages
from nnql_swarm.protocol.actions import DOWN, LEFT, N_ACTIONS, RIGHT, STAY, UP
from nnql_swarm.protocol.keys import MAX_TICK
from nnql_swarm.protocol.inbox import Inbox
from nnql_swarm.protocol.messages import (
    Answer,
    CONTROL_SHUTDOWN,
    MAX_AGENTS,
    MAX_GRID,
    MAX_PAYLOAD_BYTES,
    MESSAGES,
    PROTOCOL_VERSION,
    WORLD_SENDER,
    Control,
    Intent,
    Observation,
    Rejected,
    agent_sender,
    encode,
    pack_ids,
    pack_neighbours,
    pack_updates,
    unpack_group,
    unpack_ids,
    unpack_neighbours,
    parse,
    to_wire,
)

RUN = "run-1"
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
KINDS = (Observation, Intent, Answer, Control)
TAG = {cls: f"{kind}/{PROTOCOL_VERSION}"
       for cls, kind in zip(KINDS, ("obs", "intent", "answer", "control"))}


def obs(**change) -> Observation:
    base = dict(
        run=RUN, tick=7, sender=WORLD_SENDER, agent=2, episode=1, step=6, position=(3, 4),
        goal=(9, 9), neighbours=pack_neighbours([(0, 3, 5), (5, 1, 1)]), rank=1, reward_ds=0.25,
        reward_ca=10.0,
        collided=False, arrived=False, episode_end=False,
    )
    return Observation(**{**base, **change})


def intent(**change) -> Intent:
    base = dict(run=RUN, tick=7, sender=agent_sender(2), agent=2, episode=1, action=3)
    return Intent(**{**base, **change})


def answer(**change) -> Answer:
    base = dict(run=RUN, tick=7, sender=agent_sender(2), agent=2, episode=1, action=3,
                relayed=((0, 4), (5, 0)))
    return Answer(**{**base, **change})


def control(**change) -> Control:
    base = dict(run=RUN, tick=7, sender=WORLD_SENDER, command=CONTROL_SHUTDOWN)
    return Control(**{**base, **change})


def fields_of(cls) -> tuple[str, ...]:
    return cls.__struct_fields__


def values(msg) -> tuple:
    return msgspec.structs.astuple(msg)


def replaced(msg, **change):
    return msgspec.structs.replace(msg, **change)


def wire_index(cls, name: str) -> int:
    """Where a field is in the wire array: after the tag, in the class's field order."""
    return 1 + fields_of(cls).index(name)


def pack(obj) -> bytes:
    return msgpack.packb(obj, use_bin_type=True)


def reason_of(payload, kind, run=RUN, key_agent=None) -> str:
    with pytest.raises(Rejected) as info:
        parse(payload, kind, run, key_agent)
    return info.value.reason


def mutated(msg, name: str, value) -> bytes:
    wire = to_wire(msg)
    wire[wire_index(type(msg), name)] = value
    return pack(wire)


# ---------------------------------------------------------------- round trips and wire format


@pytest.mark.parametrize("msg", [obs(), obs(neighbours=b""), intent(), intent(order=(3, 0, 4)),
                                 control()])
def test_round_trip(msg):
    payload = encode(msg)
    assert isinstance(payload, bytes)
    back = parse(payload, type(msg), RUN)
    assert back == msg and type(back) is type(msg)
    assert parse(zenoh.ZBytes(payload), type(msg), RUN) == msg
    assert parse(bytearray(payload), type(msg), RUN) == msg
    assert parse(memoryview(payload), type(msg), RUN) == msg


def test_an_intent_with_its_order_of_moves_round_trips():
    """Protocol 8: under ``--arbitration pibt`` an intent also carries ``order``, the agent's moves
    in its order of preference, its announced action first and each move at most once. The world
    (``world.arbiter``) settles every agent's move from these orders by priority inheritance
    (``world.pibt.plan``): an agent gets the first move of its order that the arbitration allows,
    else a later one, and a move left out of its order is one it does not want; a missed intent
    offers only STAY. An empty order (the default) is an intent of the other arbitrations."""
    for order in ((3,), (3, 0), (3, 0, 4), (3, 4, 2, 1, 0), (RIGHT, STAY, UP, DOWN, LEFT)):
        msg = intent(order=order)
        payload = encode(msg)
        assert msgpack.unpackb(payload) == ["intent/11", RUN, 7, "agent/2", 2, 1, 3, [], list(order),
                                            0]
        for form in (bytes, bytearray, memoryview, zenoh.ZBytes):
            back = parse(form(payload), Intent, RUN, key_agent=2)
            assert back == msg and back.order == order and type(back.order) is tuple
        assert Inbox(RUN).decode(payload, Intent, key_agent=2) == msg
    stay = intent(action=STAY, order=(STAY, LEFT))  # parked: it offers to stay, may be pushed
    assert parse(encode(stay), Intent, RUN).order == (STAY, LEFT)
    assert intent(order=()) == intent() and intent().order == ()
    assert parse(encode(intent(order=[3, 1])), Intent, RUN).order == (3, 1)  # a list: a tuple
    assert parse(encode(intent(order=np.array([3, 1]))), Intent, RUN).order == (3, 1)
    with_record = intent(record=(((0, 1, -1), (0.5, -1.0)),), order=(3, 1))
    assert parse(encode(with_record), Intent, RUN) == with_record


def test_wire_format_is_an_array_of_the_tag_and_fields_in_order():
    assert PROTOCOL_VERSION == 11
    wire = msgpack.unpackb(encode(intent()))
    assert wire == ["intent/11", RUN, 7, "agent/2", 2, 1, 3, [], [], 0]
    assert msgpack.unpackb(encode(control())) == ["control/11", RUN, 7, WORLD_SENDER, "shutdown"]
    assert msgpack.unpackb(encode(obs()))[0] == "obs/11"
    assert msgpack.unpackb(encode(obs(world=3)))[-1] == 3
    assert msgpack.unpackb(encode(answer()))[-1] == [[0, 4], [5, 0]]
    assert MESSAGES == KINDS
    for cls in MESSAGES:
        assert cls.__struct_config__.tag == TAG[cls] == messages.tag(TAG[cls].split("/")[0])
        assert fields_of(cls)[:3] == ("run", "tick", "sender")
        msg = {Observation: obs, Intent: intent, Answer: answer, Control: control}[cls]()
        assert msgpack.unpackb(encode(msg), use_list=False) == (TAG[cls], *values(msg))
    assert len(set(TAG.values())) == len(MESSAGES)


def test_messages_are_immutable_structs():
    msg = intent()
    assert isinstance(msg, msgspec.Struct) and msg == Intent(RUN, 7, "agent/2", 2, 1, 3)
    assert (msg.run, msg.tick, msg.sender, msg.agent, msg.episode, msg.action,
            msg.record, msg.order, msg.world) == values(msg)
    with pytest.raises(AttributeError):
        msg.action = 4
    assert replaced(msg, action=4).action == 4 and msg.action == 3
    assert hash(msg) == hash(intent()) and Intent.__doc__.startswith("Agent -> world")
    assert fields_of(Intent)[-1] == "world" and msg.order == () and intent(order=()) == msg
    assert intent(order=(3, 1)) != msg
    assert obs() == Observation(*values(obs())) == Observation(**msgspec.structs.asdict(obs()))
    assert msg != answer(relayed=()) and intent(record=()) == msg


def test_encode_normalises_numpy_and_ints():
    msg = obs(agent=np.int64(2), position=np.array([3, 4]), goal=(np.int32(9), 9),
              neighbours=pack_neighbours(np.array([[0, 3, 5], [5, 1, 1]])),
              reward_ds=np.float32(0.25), reward_ca=10, collided=np.bool_(False),
              tick=np.uint64(7))
    back = parse(encode(msg), Observation, RUN)
    assert back == obs()
    assert type(back.reward_ca) is float and type(back.agent) is int and type(back.collided) is bool
    assert unpack_neighbours(back.neighbours).tolist() == [[0, 3, 5], [5, 1, 1]]
    assert type(back.position) is tuple


@pytest.mark.parametrize("msg,reason", [
    (obs(agent=True), "bad-field:agent"), (obs(position=(1, 2, 3)), "bad-field:position"),
    (obs(reward_ds=math.nan), "bad-field:reward_ds"),
    (obs(neighbours=pack_neighbours([(0, 3, 5)])[:4]), "bad-field:neighbours"),
    (obs(neighbours=((0, 3, 5),)), "bad-field:neighbours"),
    (obs(parked=b"\x05"), "bad-field:parked"),
    (obs(sender="agent/2"), "forged-sender"),
    (intent(action=N_ACTIONS), "bad-field:action"), (intent(sender="agent/3"), "forged-sender"),
    (intent(action=1.0), "bad-field:action"), (control(command="reboot"), "bad-field:command"),
    (intent(order=(2, 3)), "bad-field:order"), (intent(order=(3, 1, 3)), "bad-field:order"),
    (intent(order=(3, 0, 1, 2, 4, 3)), "bad-field:order"),  # too long
    (intent(order=(3, 5)), "bad-field:order"),
    (intent(order=(3, -1)), "bad-field:order"), (intent(order=(3, True)), "bad-field:order"),
    (intent(order=(3.0,)), "bad-field:order"), (intent(order=(4, 3)), "bad-field:order"),
    (intent(order=(3, 3)), "bad-field:order"), (intent(order="ab"), "bad-field:order"),
    (intent(order=((3,),)), "bad-field:order"), (intent(order=None), "bad-field:order"),
    (intent(order=(3, 0), sender="agent/3"), "forged-sender"),
    (control(run="a/b"), "bad-field:run"), (control(tick=-1), "bad-field:tick"),
])
def test_an_invalid_message_is_refused_where_it_arrives(msg, reason):
    """encode packs what msgpack can carry (a bad run id aside); the receiver names the rule."""
    if reason == "bad-field:run":
        with pytest.raises(Rejected) as rejected:
            encode(msg)
    else:
        with pytest.raises(Rejected) as rejected:
            parse(encode(msg), type(msg), msg.run)
    assert rejected.value.reason == reason
    assert isinstance(rejected.value, ValueError)


def test_encode_rejects_non_messages():
    with pytest.raises(TypeError):
        encode({"v": 1})
    with pytest.raises(TypeError):
        encode(values(intent()))  # the same values, but not a message
    with pytest.raises(TypeError):
        encode(messages.Message(RUN, 7, "world"))  # the header of every kind, but of none
    with pytest.raises(TypeError):
        parse(encode(intent()), dict, RUN)
    for kind in (dict, tuple, [Intent], None):
        with pytest.raises(TypeError, match="not a message class"):
            Inbox(RUN).decode(encode(intent()), kind)  # a bug in the caller: raised, not counted


# ---------------------------------------------------------------- every rejection reason


def test_rejection_reasons():
    good = encode(intent())
    assert reason_of(None, Intent) == "not-bytes"
    assert reason_of("text", Intent) == "not-bytes"
    assert reason_of(12, Intent) == "not-bytes"
    assert reason_of(b"\xc1", Intent) == "not-msgpack"  # never-used byte
    assert reason_of(good[:-1], Intent) == "not-msgpack"  # truncated
    assert reason_of(good + b"\x00", Intent) == "not-msgpack"  # trailing data
    assert reason_of(pack(msgpack.ExtType(3, b"x")), Intent) == "not-msgpack"  # ext type
    assert reason_of(pack(msgpack.Timestamp(1, 0)), Intent) == "not-msgpack"  # built-in ext -1
    assert reason_of(pack([TAG[Intent], {1: 2}]), Intent) == "not-msgpack"  # a map inside
    assert reason_of(pack("a" * 1000), Intent) == "not-msgpack"  # over max_str_len
    assert reason_of(b"\xa1\xff", Intent) == "not-msgpack"  # invalid UTF-8
    assert reason_of(pack([0] * (MAX_AGENTS + 1)), Intent) == "not-msgpack"  # over max_array_len
    assert reason_of(b"\x91" * 5000 + b"\x00", Intent) == "not-msgpack"  # nesting too deep
    assert reason_of(pack(None), Intent) == "not-array"
    assert reason_of(pack("intent"), Intent) == "not-array"
    assert reason_of(pack({1: 2}), Intent) == "not-array"  # a map, whatever its keys
    wire = to_wire(intent())
    for other in (f"intent/{PROTOCOL_VERSION - 1}", f"intent/{PROTOCOL_VERSION + 1}", "intent",
                  PROTOCOL_VERSION, True, 2.0, None, [TAG[Intent]], "Intent/8", b"intent/8",
                  "intent/7", "obs/7"):
        assert reason_of(pack([other, *wire[1:]]), Intent) == "bad-version", other
    assert reason_of(pack([6, "intent", *wire[1:]]), Intent) == "bad-version"  # version 6
    assert reason_of(pack(wire[1:]), Intent) == "bad-version"  # no tag: the run in its place
    assert reason_of(pack([1, 2]), Intent) == "bad-version"
    assert reason_of(encode(control()), Intent) == "wrong-kind"
    assert reason_of(pack([TAG[Answer], *wire[1:]]), Intent) == "wrong-kind"  # as long
    assert reason_of(pack(wire[:-1]), Intent) == "wrong-length"  # no order
    assert reason_of(pack([*wire, 1]), Intent) == "wrong-length"  # an item too many
    assert reason_of(good, Intent, run="run-2") == "wrong-run"
    assert reason_of(pack([*wire[:1], 1, *wire[2:]]), Intent) == "wrong-run"
    assert reason_of(mutated(intent(), "action", 5), Intent) == "bad-field:action"
    assert reason_of(mutated(intent(), "order", [3, 5]), Intent) == "bad-field:order"
    assert reason_of(mutated(intent(), "order", [3, 1, 3]), Intent) == "bad-field:order"
    assert reason_of(mutated(intent(), "order", [1, 3]), Intent) == "bad-field:order"
    assert reason_of(mutated(intent(), "order", None), Intent) == "bad-field:order"
    assert parse(mutated(intent(), "order", [3, 1]), Intent, RUN) == intent(order=(3, 1))
    assert reason_of(mutated(intent(), "sender", "agent/3"), Intent) == "forged-sender"
    assert reason_of(mutated(intent(), "sender", "world"), Intent) == "forged-sender"
    assert reason_of(mutated(intent(), "sender", 2), Intent) == "bad-field:sender"
    assert reason_of(good, Intent, key_agent=3) == "forged-sender"
    assert parse(good, Intent, RUN, key_agent=2) == intent()
    assert reason_of(mutated(obs(), "sender", "agent/2"), Observation) == "forged-sender"
    assert reason_of(mutated(control(), "sender", "agent/0"), Control) == "forged-sender"
    assert reason_of(mutated(control(), "command", "reboot"), Control) == "bad-field:command"


def detail_of(payload, kind, run=RUN, key_agent=None) -> str:
    with pytest.raises(Rejected) as info:
        parse(payload, kind, run, key_agent)
    return str(info.value)


def test_wrong_length_says_how_many_items():
    wire = to_wire(intent())
    assert detail_of(pack(wire[:-1]), Intent) == "wrong-length: expected 10 items, got 9"
    assert detail_of(pack([*wire, 0, 0]), Intent) == "wrong-length: expected 10 items, got 12"
    assert detail_of(pack([]), Intent) == "wrong-length: expected 10 items, got 0"
    assert detail_of(pack([TAG[Intent]]), Intent) == "wrong-length: expected 10 items, got 1"
    assert detail_of(pack([TAG[Intent], RUN]), Intent) == "wrong-length: expected 10 items, got 2"
    full = to_wire(obs())
    assert detail_of(pack(full[:5]), Observation) == "wrong-length: expected 20 items, got 5"
    short = pack(to_wire(answer())[:-1])
    assert detail_of(short, Answer) == "wrong-length: expected 8 items, got 7"
    for cut in (to_wire(obs())[:-3], to_wire(intent())[:-1]):  # fields with defaults: not optional
        assert reason_of(pack(cut), Observation if cut[0] == TAG[Observation] else Intent) \
            == "wrong-length"


def test_checks_come_in_order_version_kind_length_run_fields_rules():
    """Each check wins over the ones after it: a message of another version or kind says so,
    whatever its length; a wrong length, whatever its items; a wrong run, whatever its fields."""
    wire = to_wire(intent())
    assert reason_of(pack([1]), Intent) == "bad-version"
    assert reason_of(pack(["obs/6"]), Intent) == "bad-version"
    assert reason_of(pack(["obs/6", *wire[1:], 0, 0]), Intent) == "bad-version"
    assert reason_of(pack(["intent/7", *wire[1:-1]]), Intent) == "bad-version"  # a version-7 intent
    assert reason_of(pack(["obs/7"]), Intent) == "bad-version"
    assert reason_of(pack(["intent"]), Intent) == "bad-version"
    assert reason_of(pack([TAG[Observation]]), Intent) == "wrong-kind"
    assert reason_of(pack([TAG[Control], *wire[1:], 0]), Intent) == "wrong-kind"
    assert reason_of(encode(obs()), Intent) == "wrong-kind"  # longer
    assert reason_of(encode(control()), Answer) == "wrong-kind"  # shorter
    assert reason_of(pack([TAG[Intent], "other-run"]), Intent) == "wrong-length"
    assert reason_of(pack([TAG[Intent], None, None, None, None, None]), Intent) == "wrong-length"
    changed = [*wire[:1], "other-run", -1, None, MAX_AGENTS, -1, 99, None, None, None]
    assert reason_of(pack(changed), Intent) == "wrong-run"
    changed = [*wire[:2], -1, "agent/3", MAX_AGENTS, -1, 99, None, None, None]
    assert reason_of(pack(changed), Intent) == "bad-field:tick"  # the first bad field
    assert reason_of(pack([*wire[:3], "agent/3", 2, 1, 99, [], [9], 0]), Intent) == \
        "bad-field:action"
    assert reason_of(pack([*wire[:3], "agent/3", 2, 1, 3, [], [9], 0]), Intent) == \
        "bad-field:order"
    # the order's rule (the action first, each move once) is a rule: after the sender
    assert reason_of(pack([*wire[:3], "agent/3", 2, 1, 3, [], [1, 3], 0]), Intent) == \
        "forged-sender"
    assert reason_of(pack([*wire[:-2], [1, 3], 0]), Intent, key_agent=3) == "forged-sender"
    assert reason_of(pack([*wire[:-2], [1, 3], 0]), Intent, key_agent=2) == "bad-field:order"
    cut_short = mutated(obs(), "neighbours", pack_neighbours([(0, 3, 5)])[:5])
    assert reason_of(cut_short, Observation) == "bad-field:neighbours"
    forged = to_wire(obs())
    forged[wire_index(Observation, "sender")] = "agent/2"
    forged[wire_index(Observation, "neighbours")] = pack_neighbours([(0, 3, 5)])[:5]
    assert reason_of(pack(forged), Observation) == "forged-sender"  # the sender before packings


def test_maps_are_not_part_of_the_wire():
    """At the top level a map is ``not-array`` (a version-1 message among them), whatever its
    size or content, told by its first byte; anywhere inside, even empty, it is ``not-msgpack``."""
    version_1 = {"v": 1, "k": "intent", "r": RUN, "t": 7, "s": "agent/2", "a": 2, "e": 1, "x": 3}
    for top in ({}, {"v": 2}, version_1, {**version_1, "v": 2}, {1: 2}, {"x": [{"y": 1}]},
                {str(i): i for i in range(100)}, {"a": "b" * 1000}):
        assert reason_of(pack(top), Intent) == "not-array", top
    assert reason_of(pack(version_1)[:3], Intent) == "not-array"  # truncated: still a map
    assert reason_of(b"\xdf\xff\xff\xff\xff", Intent) == "not-array"  # map 32, 4 billion pairs
    assert reason_of(b"\xde\x00\x01", Intent) == "not-array"  # map 16
    wire = to_wire(intent())
    for inner in ({}, {"a": 1}, {1: 2}):
        for i in range(len(wire)):
            assert reason_of(pack([*wire[:i], inner, *wire[i + 1:]]), Intent) == "not-msgpack"
        assert reason_of(pack([*wire, inner]), Intent) == "not-msgpack"
    assert reason_of(mutated(obs(), "neighbours", [[1, 0, 0], {}]), Observation) == "not-msgpack"
    for name in ("goal", "position", "collided", "reward_ds"):
        assert reason_of(mutated(obs(), name, {"x": 1}), Observation) == "not-msgpack"


def test_largest_observation_fits():
    crowd = [(a, a % MAX_GRID, MAX_GRID - 1) for a in range(1, MAX_AGENTS)]
    msg = obs(agent=0, neighbours=pack_neighbours(crowd), parked=pack_ids(range(1, MAX_AGENTS)),
              tick=MAX_TICK - 1, episode=MAX_TICK - 1, step=MAX_TICK - 1, reward_ds=-1e6,
              reward_ca=1e6)
    payload = encode(msg)
    assert len(payload) < MAX_PAYLOAD_BYTES // 4
    assert parse(payload, Observation, RUN) == msg


@pytest.mark.parametrize("name,value", [
    ("tick", -1), ("tick", MAX_TICK), ("tick", 1.0), ("tick", True), ("tick", "7"), ("tick", None),
    ("agent", MAX_AGENTS), ("agent", -1), ("episode", -1), ("step", MAX_TICK), ("rank", MAX_AGENTS),
    ("position", [MAX_GRID, 0]), ("position", [0, -1]), ("position", [1]), ("position", [1, 2, 3]),
    ("position", [True, 0]), ("position", [1.0, 2]), ("position", "ab"), ("goal", [[1, 2]]),
    ("neighbours", [[1, 0, 0]]), ("neighbours", b"\x01\x00\x00\x00\x00"),
    ("neighbours", bytes(6 * MAX_AGENTS + 6)), ("neighbours", [1, 2, 3]), ("neighbours", None),
    ("parked", [1]), ("parked", b"\x01"), ("parked", bytes(2 * MAX_AGENTS + 2)),
    ("reward_ds", math.nan), ("reward_ds", math.inf), ("reward_ca", -math.inf),
    ("reward_ca", 1e6 + 1), ("reward_ds", -(10**7)), ("reward_ds", True), ("reward_ds", "1"),
    ("collided", 1), ("arrived", 0), ("episode_end", None), ("collided", 1.0),
])
def test_observation_bad_fields(name, value):
    assert reason_of(mutated(obs(), name, value), Observation) == f"bad-field:{name}"


def test_float_fields_accept_ints():
    assert parse(mutated(obs(), "reward_ca", 10), Observation, RUN).reward_ca == 10.0


# ---------------------------------------------------------------- Inbox


def test_inbox_never_raises_counts_and_accepts():
    inbox = Inbox(RUN)
    assert inbox.decode(encode(intent()), Intent, key_agent=2) == intent()
    assert inbox.decode(zenoh.ZBytes(encode(obs())), Observation) == obs()
    assert inbox.accepted == 2
    for junk in (None, "str", 3, 2.5, [1], b"", object(), zenoh.ZBytes(b"\x00"), encode(control())):
        assert inbox.decode(junk, Intent) is None
    assert inbox.rejections["not-bytes"] == 6
    assert inbox.rejections["not-msgpack"] == 1
    assert inbox.rejections["not-array"] == 1
    assert inbox.rejections["wrong-kind"] == 1
    assert inbox.reject("stale-tick", "tick 3 < 7") is None
    assert inbox.rejections["stale-tick"] == 1
    assert inbox.total_rejected == 10
    assert inbox.accepted == 2
    with pytest.raises(ValueError):
        Inbox("bad/run")


def test_inbox_survives_a_payload_whose_to_bytes_fails():
    class Weird:
        def to_bytes(self):
            raise RuntimeError("nope")

        def __len__(self):
            raise RuntimeError("nope either")

    inbox = Inbox(RUN)
    assert inbox.decode(Weird(), Intent) is None
    assert inbox.total_rejected == 1


def test_inbox_log_is_rate_limited(caplog):
    logger = logging.getLogger("test.inbox")
    inbox = Inbox(RUN, logger=logger)
    with caplog.at_level(logging.WARNING, logger="test.inbox"):
        for _ in range(2500):
            inbox.decode(b"\xc1", Intent)
        inbox.reject("stale-tick")
    records = [r for r in caplog.records if r.name == "test.inbox"]
    assert len(records) == Inbox.LOG_FIRST + 2 + 1  # first 10, 1000th, 2000th, and stale-tick
    assert all(r.levelno == logging.WARNING for r in records)
    assert "not-msgpack" in records[0].getMessage() and "stale-tick" in records[-1].getMessage()
    assert inbox.rejections["not-msgpack"] == 2500


# ---------------------------------------------------------------- hypothesis

run_ids = st.from_regex(keys.RUN_ID_PATTERN, fullmatch=True)
counts = st.integers(0, MAX_TICK - 1)
agents = st.integers(0, MAX_AGENTS - 1)
coords = st.integers(0, MAX_GRID - 1)
cells = st.tuples(coords, coords)
rewards = st.floats(-1e6, 1e6, allow_nan=False) | st.integers(-(10**6), 10**6).map(float)


_update_groups = st.integers(0, 4).flatmap(lambda k: st.tuples(
    st.binary(min_size=2 * k, max_size=2 * k), st.binary(min_size=8 * k, max_size=8 * k)))
"""A group of the shared table's updates, packed: its content is the receiver's to check."""


@st.composite
def observations(draw, run=None):
    agent = draw(agents)
    ids = draw(st.lists(agents.filter(lambda a: a != agent), unique=True, max_size=12))
    return Observation(
        run=run or draw(run_ids), tick=draw(counts), sender=WORLD_SENDER, agent=agent,
        episode=draw(counts), step=draw(counts), position=draw(cells), goal=draw(cells),
        neighbours=pack_neighbours([(i, draw(coords), draw(coords)) for i in ids]),
        parked=pack_ids(draw(st.lists(agents, max_size=4))), rank=draw(agents),
        reward_ds=draw(rewards), reward_ca=draw(rewards), collided=draw(st.booleans()),
        arrived=draw(st.booleans()), episode_end=draw(st.booleans()), settled=draw(st.booleans()),
        updates=tuple(draw(st.lists(_update_groups, max_size=2))),
    )


@st.composite
def orders(draw, action):
    """A valid order for ``action``: none, or the action first, then other moves, each once."""
    others = draw(st.permutations([a for a in range(N_ACTIONS) if a != action]))
    size = draw(st.integers(0, N_ACTIONS))
    return (action, *others[:size - 1]) if size else ()


@st.composite
def intents(draw, run=None):
    agent = draw(agents)
    action = draw(st.integers(0, N_ACTIONS - 1))
    return Intent(run=run or draw(run_ids), tick=draw(counts), sender=agent_sender(agent),
                  agent=agent, episode=draw(counts), action=action, order=draw(orders(action)))


def controls(run=None):
    commands = st.sampled_from(sorted(messages.CONTROL_COMMANDS))
    return st.builds(Control, run=st.just(run) if run else run_ids, tick=counts,
                     sender=st.just(WORLD_SENDER), command=commands)


@st.composite
def answers(draw, run=None):
    agent = draw(agents)
    others = draw(st.lists(agents.filter(lambda a: a != agent), unique=True, max_size=12))
    return Answer(run=run or draw(run_ids), tick=draw(counts), sender=agent_sender(agent),
                  agent=agent, episode=draw(counts), action=draw(st.integers(0, N_ACTIONS - 1)),
                  relayed=tuple((j, draw(st.integers(0, N_ACTIONS - 1))) for j in others))


any_message = observations() | intents() | answers() | controls()


@given(st.binary(max_size=300), st.sampled_from(KINDS))
@FUZZ
def test_fuzz_arbitrary_bytes_never_raise(payload, kind):
    inbox = Inbox(RUN)
    assert inbox.decode(payload, kind) is None
    assert inbox.total_rejected == 1


@given(any_message, st.data())
@FUZZ
def test_fuzz_corrupted_valid_bytes_never_raise(msg, data):
    payload = bytearray(encode(msg))
    for _ in range(data.draw(st.integers(1, 3))):
        payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    cut = data.draw(st.integers(0, len(payload)))
    inbox = Inbox(msg.run)
    got = inbox.decode(bytes(payload[:cut]), type(msg))
    if got is not None:  # a corruption can still be a valid message (another tick, say)
        assert type(got) is type(msg) and parse(encode(got), type(msg), msg.run) == got
    assert inbox.accepted + inbox.total_rejected == 1


@given(any_message)
@FUZZ
def test_fuzz_valid_messages_round_trip_exactly(msg):
    back = parse(encode(msg), type(msg), msg.run)
    assert back == msg
    assert [type(getattr(back, f)) for f in fields_of(type(msg))] == [
        type(getattr(msg, f)) for f in fields_of(type(msg))
    ]
    assert encode(back) == encode(msg)


# Single-field mutations: a value that is wrong for the field (type or range) names that field.

_small_ints = st.integers(-99, 99)
_wrong_types = (
    st.none() | st.text(max_size=8) | st.binary(max_size=8) | st.lists(_small_ints, max_size=2)
    | st.dictionaries(st.text(max_size=2), _small_ints, max_size=2)
)
_bad_int = _wrong_types | st.booleans() | st.floats()


def _out_of(lo: int, hi: int):
    """Ints msgpack can carry but outside [lo, hi)."""
    return st.integers(-(2**63), lo - 1) | st.integers(hi, 2**64 - 1)


_bad_coord = _bad_int | _out_of(0, MAX_GRID)
_bad_cell = (
    _wrong_types.filter(lambda v: not isinstance(v, list))
    | st.lists(coords, max_size=5).filter(lambda v: len(v) != 2)
    | st.tuples(_bad_coord, coords).map(list)
    | st.tuples(coords, _bad_coord).map(list)
)
_bad_neighbours = (  # packed (id, x, y), 2 bytes each: whether they fit the run is the plan's
    _wrong_types.filter(lambda v: not isinstance(v, bytes))
    | st.lists(st.tuples(agents, coords, coords), max_size=3).map(lambda v: [list(t) for t in v])
    .filter(bool)  # unpacked
    | st.binary(max_size=20).filter(lambda v: len(v) % 6)  # cut short
    | st.just(bytes(6 * MAX_AGENTS + 6))  # too long
)
_bad_relayed = (
    _wrong_types.filter(lambda v: not isinstance(v, list) or v)  # [] is valid
    | st.lists(_wrong_types.filter(lambda v: not (isinstance(v, list) and len(v) == 2))
               | st.lists(coords, max_size=5).filter(lambda v: len(v) != 2),
               min_size=1, max_size=3)  # (a pair of small ints is an entry: [0, 0])
    | st.tuples(_bad_int | _out_of(0, MAX_AGENTS), st.integers(0, N_ACTIONS - 1))
      .map(lambda t: [list(t)])
    | st.tuples(agents, _bad_int | _out_of(0, N_ACTIONS)).map(lambda t: [list(t)])
    | st.tuples(agents, st.integers(0, N_ACTIONS - 1)).map(lambda t: [list(t), list(t)])
)
_bad_reward = (
    _wrong_types | st.booleans() | st.sampled_from([math.nan, math.inf, -math.inf])
    | st.floats(min_value=1e6, exclude_min=True) | st.floats(max_value=-1e6, exclude_max=True)
    | st.integers(10**6 + 1, 2**63) | st.integers(-(2**63), -(10**6) - 1)
)
_bad_bool = _wrong_types | _small_ints | st.floats()
_bad_parked = (_wrong_types.filter(lambda v: not isinstance(v, bytes))
               | st.lists(agents, min_size=1, max_size=3)  # unpacked
               | st.binary(max_size=9).filter(lambda v: len(v) % 2)  # cut short
               | st.just(bytes(2 * MAX_AGENTS + 2)))  # too long
_record_ints = st.lists(st.integers(-1, 441 * 6 - 1), max_size=6)
_rewards = st.tuples(st.floats(-1e6, 1e6), st.floats(-1e6, 1e6)).map(list)
_bad_record_ints = (_wrong_types.filter(lambda v: not isinstance(v, list))  # [0] is valid
                    | st.lists(_bad_int | _out_of(-1, 441 * 6), min_size=1, max_size=3))
_bad_rewards = _wrong_types.filter(lambda v: not (isinstance(v, list) and len(v) == 2)) \
    | st.lists(_bad_reward, min_size=2, max_size=2) \
    | st.lists(st.floats(-1.0, 1.0), min_size=3, max_size=4)
_not_binary = _wrong_types.filter(lambda v: not isinstance(v, bytes))
_bad_updates = (
    _wrong_types.filter(lambda v: not isinstance(v, list) or v)
    | st.tuples(_not_binary, st.binary(max_size=8)).map(lambda t: [list(t)])  # entries unpacked
    | st.tuples(st.binary(max_size=8), _not_binary).map(lambda t: [list(t)])  # values unpacked
    | st.binary(max_size=8).map(lambda e: [[e]])  # entries without their values
    | _wrong_types.filter(lambda v: not isinstance(v, list) or v).map(lambda v: [v])
    | st.binary(max_size=9).filter(lambda e: len(e) % 2).map(lambda e: [[e, b""]])  # cut short
    | st.binary(max_size=15).filter(lambda v: len(v) % 8).map(lambda v: [[b"", v]])
    # a group of more entries than a field may hold (its values at the longest binary the wire
    # carries: a longer one, anywhere, is not-msgpack)
    | st.just([[bytes(2 * MAX_AGENTS + 2), bytes(8 * MAX_AGENTS)]])
)
_bad_record = (
    _wrong_types.filter(lambda v: not isinstance(v, list) or v)
    | st.tuples(_bad_record_ints, _rewards).map(lambda t: [list(t)])
    | st.tuples(_record_ints, _bad_rewards).map(lambda t: [list(t)])
    | st.tuples(_record_ints, _rewards).map(lambda t: [list(t), list(t)])  # two: at most one
)
_bad_command = st.text(max_size=10).filter(lambda c: c not in messages.CONTROL_COMMANDS)
_moves = st.integers(0, N_ACTIONS - 1)
_bad_order = (
    _wrong_types.filter(lambda v: not isinstance(v, list))  # [] is valid, and [action]
    | st.lists(_wrong_types | st.booleans() | st.floats(), min_size=1, max_size=3).map(
        lambda v: [0, *v])  # a move of another type
    | st.lists(_moves, min_size=1, max_size=3).flatmap(  # a move out of range, anywhere
        lambda v: st.tuples(st.just(v), st.integers(0, len(v)), _out_of(0, N_ACTIONS)))
    .map(lambda t: [*t[0][:t[1]], t[2], *t[0][t[1]:]])
    | st.lists(_moves, min_size=N_ACTIONS + 1, max_size=N_ACTIONS + 3)  # too long
    | st.permutations(range(N_ACTIONS)).map(lambda p: [*p, p[0]])  # too long, by a repeat
    | st.lists(_moves, min_size=1, max_size=3).map(lambda v: [v[0], *v])  # a move twice, first
    | st.lists(_moves, min_size=2, max_size=3).map(lambda v: [*v, v[-1]])  # a move twice
)


def _bad_order_for(action: int):
    """Orders each move valid but against the rule for an intent of ``action``: not the action
    first, or the action twice (each move once)."""
    others = [a for a in range(N_ACTIONS) if a != action]
    return (st.permutations(others).flatmap(lambda p: st.integers(1, len(p)).map(
        lambda k: list(p[:k])))  # without the action, or the action not first
            | st.permutations(others).flatmap(lambda p: st.integers(0, len(p)).map(
                lambda k: [*p[:k], action, *p[k:]][:N_ACTIONS]))
            .filter(lambda v: v[0] != action)
            | st.permutations(others).flatmap(lambda p: st.integers(0, len(p) - 1).map(
                lambda k: [action, *p[:k], action])))

BAD = {
    "run": _wrong_types | run_ids, "sender": _wrong_types | st.text(max_size=12),
    "tick": _bad_int | _out_of(0, MAX_TICK), "episode": _bad_int | _out_of(0, MAX_TICK),
    "step": _bad_int | _out_of(0, MAX_TICK), "agent": _bad_int | _out_of(0, MAX_AGENTS),
    "rank": _bad_int | _out_of(0, MAX_AGENTS), "action": _bad_int | _out_of(0, N_ACTIONS),
    "position": _bad_cell, "goal": _bad_cell, "neighbours": _bad_neighbours,
    "reward_ds": _bad_reward, "reward_ca": _bad_reward,
    "collided": _bad_bool, "arrived": _bad_bool, "episode_end": _bad_bool, "settled": _bad_bool,
    "command": _wrong_types | _bad_command, "relayed": _bad_relayed,
    "parked": _bad_parked, "updates": _bad_updates, "record": _bad_record, "order": _bad_order,
    "world": _bad_int | _out_of(0, MAX_TICK),
}
BAD_FOR = {"order": lambda msg: _bad_order_for(msg.action)}
"""Bad values that depend on the message's other fields (the rules between fields)."""


def _has_map(value) -> bool:
    return isinstance(value, dict) or isinstance(value, list) and any(map(_has_map, value))


@given(any_message, st.data())
@FUZZ
def test_fuzz_single_field_mutations_are_rejected_naming_the_field(msg, data):
    """A value that is wrong for the field names the field (a map, anywhere, is not-msgpack)."""
    cls = type(msg)
    name = data.draw(st.sampled_from(fields_of(cls)))
    bad = BAD[name] | BAD_FOR[name](msg) if name in BAD_FOR else BAD[name]
    value = data.draw(bad)
    if _has_map(value):
        expected = {"not-msgpack"}
    elif name == "run":
        expected = {"wrong-run"}
        if value == msg.run:
            return
    elif name == "sender":
        if value == msg.sender:
            return
        expected = {"forged-sender"} if isinstance(value, str) else {"bad-field:sender"}
    else:
        expected = {f"bad-field:{name}"}
    assert reason_of(mutated(msg, name, value), cls, msg.run) in expected


def test_packed_neighbours_are_the_receivers_to_judge_once_whole():
    """The codec checks that an observation's packed neighbours and parked ids are whole; which
    agents they name (one of the run's, on its grid, once, not the receiver itself) the receiver's
    plan judges before any kernel reads them (``tests/test_agent_machine.py``)."""
    for rows in ([(2, 0, 0)], [(5, 1, 1), (5, 2, 2)], [(MAX_AGENTS + 7, MAX_GRID + 3, 65535)]):
        msg = parse(encode(obs(neighbours=pack_neighbours(rows), parked=pack_ids([2, 2]))),
                    Observation, RUN)
        assert unpack_neighbours(msg.neighbours).tolist() == [list(row) for row in rows]
        assert unpack_ids(msg.parked).tolist() == [2, 2]
    for cut in range(1, 6):
        assert reason_of(encode(obs(neighbours=pack_neighbours([(0, 3, 5)])[:cut])),
                         Observation) == "bad-field:neighbours"
    assert reason_of(encode(obs(parked=b"\x05")), Observation) == "bad-field:parked"


# Arbitrary msgpack structures, and near-valid arrays, against an independent reading of the rules.

scalars = st.none() | st.booleans() | st.integers(-(2**63), 2**64 - 1) | st.floats() \
    | st.text(max_size=20) | st.binary(max_size=20)
structures = st.recursive(
    scalars,
    lambda inner: st.lists(inner, max_size=4)
    | st.dictionaries(st.text(max_size=3), inner, max_size=4),
    max_leaves=20,
)


def _is_int(v, lo, hi):
    return type(v) is int and lo <= v < hi


def _is_cell(v):
    return type(v) is list and len(v) == 2 and all(_is_int(c, 0, MAX_GRID) for c in v)


def _is_reward(v):
    return type(v) in (int, float) and math.isfinite(v) and abs(v) <= 1e6


def _is_record_ints(v):
    return type(v) is list and len(v) <= 8 + 2 * MAX_AGENTS and all(
        _is_int(i, -1, 441 * 6) for i in v)


def _is_reward_pair(v):
    return type(v) is list and len(v) == 2 and all(_is_reward(r) for r in v)


def _is_agent_list(v, *rest):
    """A list of at most MAX_AGENTS ``[agent id, *rest]`` entries, each item valid (ids unchecked
    for repeats: that is a rule between entries)."""
    return type(v) is list and len(v) <= MAX_AGENTS and all(
        type(e) is list and len(e) == 1 + len(rest) and _is_int(e[0], 0, MAX_AGENTS)
        and all(valid(x) for valid, x in zip(rest, e[1:])) for e in v)


REFERENCE_KINDS = {  # the kind, then the fields in wire order
    Observation: ("obs run tick sender agent episode step position goal neighbours rank reward_ds "
                  "reward_ca collided arrived episode_end parked updates settled world"),
    Intent: "intent run tick sender agent episode action record order world",
    Answer: "answer run tick sender agent episode action relayed",
    Control: "control run tick sender command",
}
REFERENCE_VERSION = "11"
REFERENCE_TAGS = {"obs/11", "intent/11", "answer/11", "control/11"}  # protocol version 11
FROM_AGENTS = (Intent, Answer)
AGENT_LISTS = ("relayed",)
REFERENCE_FIELDS = {
    "run": lambda v: type(v) is str, "sender": lambda v: type(v) is str,
    "tick": lambda v: _is_int(v, 0, MAX_TICK), "episode": lambda v: _is_int(v, 0, MAX_TICK),
    "step": lambda v: _is_int(v, 0, MAX_TICK), "agent": lambda v: _is_int(v, 0, MAX_AGENTS),
    "rank": lambda v: _is_int(v, 0, MAX_AGENTS), "action": lambda v: _is_int(v, 0, 5),
    "position": _is_cell, "goal": _is_cell, "reward_ds": _is_reward, "reward_ca": _is_reward,
    "collided": lambda v: type(v) is bool, "arrived": lambda v: type(v) is bool,
    "episode_end": lambda v: type(v) is bool, "command": lambda v: v == "shutdown",
    "settled": lambda v: type(v) is bool,
    "world": lambda v: _is_int(v, 0, MAX_TICK),
    "neighbours": lambda v: type(v) is bytes and len(v) <= 6 * MAX_AGENTS,
    "relayed": lambda v: _is_agent_list(v, lambda a: _is_int(a, 0, 5)),
    "parked": lambda v: type(v) is bytes and len(v) <= 2 * MAX_AGENTS,
    "updates": lambda v: type(v) is list and len(v) <= MAX_AGENTS + 2 and all(
        type(g) is list and len(g) == 2 and type(g[0]) is bytes and type(g[1]) is bytes
        and len(g[0]) <= 2 * MAX_AGENTS and len(g[1]) <= 8 * MAX_AGENTS for g in v),
    "order": lambda v: type(v) is list and len(v) <= 5 and all(_is_int(a, 0, 5) for a in v),
    "record": lambda v: type(v) is list and len(v) <= 1 and all(
        type(e) is list and len(e) == 2 and _is_record_ints(e[0]) and _is_reward_pair(e[1])
        for e in v),
}
MAP_HEADS = {*range(0x80, 0x90), 0xDE, 0xDF}


def _refuse(*_):
    raise ValueError("not allowed")


def _strict_unpack(payload: bytes):
    """msgpack (the other library) with no maps, no ext types, and the protocol's lengths:
    strings of at most 256 characters, binaries of 8 bytes a value of MAX_AGENTS, arrays of
    MAX_AGENTS items."""
    d = msgpack.unpackb(payload, raw=False, ext_hook=_refuse, max_ext_len=0, object_hook=_refuse,
                        max_map_len=0, max_bin_len=8 * MAX_AGENTS, max_array_len=MAX_AGENTS)
    stack = [d]
    while stack:
        v = stack.pop()
        if type(v) is list:
            stack.extend(v)
        elif type(v) is str and len(v) > 256:
            raise ValueError("string too long")
    return d


def reference_reason(payload: bytes, cls, run, key_agent=None) -> str | None:
    """The protocol's rules written out again, independently of messages.py: None for a valid
    message, else the reason of the first rule the payload breaks."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        return "oversize"
    if payload[:1] and payload[0] in MAP_HEADS:
        return "not-array"
    try:
        d = _strict_unpack(payload)
    except Exception:
        return "not-msgpack"
    kind, *names = REFERENCE_KINDS[cls].split()
    if type(d) is not list:
        return "not-array"
    if d and not (type(d[0]) is str and d[0] in REFERENCE_TAGS):
        return "bad-version"
    if d and d[0] != kind + "/" + REFERENCE_VERSION:
        return "wrong-kind"
    if len(d) != 1 + len(names):
        return "wrong-length"
    m = dict(zip(names, d[1:]))
    if m["run"] != run:
        return "wrong-run"
    for name in names:
        if not REFERENCE_FIELDS[name](m[name]):
            return f"bad-field:{name}"
    lists = [name for name in names if name in AGENT_LISTS]
    for name in lists:
        if len({e[0] for e in m[name]}) != len(m[name]):
            return f"bad-field:{name}"
    if m["sender"] != (f"agent/{m['agent']}" if cls in FROM_AGENTS else "world"):
        return "forged-sender"
    if cls in FROM_AGENTS and key_agent is not None and key_agent != m["agent"]:
        return "forged-sender"
    if len(m.get("neighbours", b"")) % 6:
        return "bad-field:neighbours"  # packed (id, x, y) of 2 bytes each: none cut short
    if len(m.get("parked", b"")) % 2:
        return "bad-field:parked"  # packed ids of 2 bytes each
    if any(len(entries) % 2 or len(values) % 8 for entries, values in m.get("updates", ())):
        return "bad-field:updates"  # packed entries of 2 bytes, values of 8: none cut short
    order = m.get("order")
    if order and (order[0] != m["action"] or sorted(set(order)) != sorted(order)):
        return "bad-field:order"  # an order: the action first, then each move at most once
    for name in lists:
        if m["agent"] in {e[0] for e in m[name]}:
            return f"bad-field:{name}"
    return None


def outcome_of(payload, cls, run=RUN, key_agent=None) -> str | None:
    """What parse makes of a payload: None if it is accepted, else the reason."""
    try:
        parse(payload, cls, run, key_agent)
    except Rejected as e:
        return e.reason
    return None


@given(structures, st.sampled_from(KINDS))
@FUZZ
def test_fuzz_arbitrary_structures_are_judged_as_the_reference_judges(obj, kind):
    inbox = Inbox(RUN)
    got = inbox.decode(pack(obj), kind)
    expected = reference_reason(pack(obj), kind, RUN)
    assert (got is None) == (expected is not None)
    assert list(inbox.rejections) == ([expected] if expected else [])


def _as_lists(value):
    """``value`` with its tuples made lists, as msgpack unpacks them."""
    return list(map(_as_lists, value)) if isinstance(value, (tuple, list)) else value


_any_order = st.lists(st.integers(0, N_ACTIONS - 1), max_size=N_ACTIONS + 1)
"""Moves in any order, maybe the action not first, maybe one twice, maybe too many."""


def _redrawn(draw, msg) -> dict:
    """For an intent, at random, its order or its action redrawn, against the order rule as often
    as not: ``{name: value}`` (none for the other kinds)."""
    if type(msg) is not Intent or not draw(st.booleans()):
        return {}
    name = draw(st.sampled_from(["order", "order", "action"]))
    if name == "order":
        return {name: tuple(draw(_any_order))}
    return {name: draw(st.integers(0, N_ACTIONS - 1))}


def _reordered(draw, msg, wire: list) -> list:
    """``wire``, the wire array of ``msg``, with :func:`_redrawn`'s change."""
    for name, value in _redrawn(draw, msg).items():
        wire[wire_index(type(msg), name)] = list(value) if name == "order" else value
    return wire


@st.composite
def near_valid_arrays(draw):
    """A valid message's wire array (an intent's maybe with its order or action redrawn) with each
    item, at random, kept, replaced by junk, or dropped, and maybe one more inserted."""
    msg = draw(any_message)
    out = []
    for v in _as_lists(_reordered(draw, msg, to_wire(msg))):
        choice = draw(st.sampled_from(["keep"] * 12 + ["junk", "drop"]))
        if choice == "keep":
            out.append(v)
        elif choice == "junk":
            out.append(draw(structures | st.integers(-3, 1100)))
    if draw(st.booleans()) and draw(st.booleans()):
        out.insert(draw(st.integers(0, len(out))), draw(scalars))
    return type(msg), msg.run, out


@given(near_valid_arrays())
@FUZZ
def test_fuzz_near_valid_arrays_are_judged_as_the_reference_judges(case):
    cls, run, obj = case
    assert outcome_of(pack(obj), cls, run) == reference_reason(pack(obj), cls, run)
    got = Inbox(run).decode(pack(obj), cls)
    if got is not None:
        assert msgpack.unpackb(encode(got)) == obj


def test_answer_rejects_relaying_itself_duplicates_and_forged_senders():
    good = Answer(run=RUN, tick=3, sender=agent_sender(2), agent=2, episode=0, action=1,
                  relayed=((0, 4), (1, 0)))
    assert parse(encode(good), Answer, RUN, key_agent=2) == good
    for bad, reason in [
        ({"relayed": ((2, 4),)}, "bad-field:relayed"),
        ({"relayed": ((0, 4), (0, 1))}, "bad-field:relayed"),
        ({"relayed": ((0, 9),)}, "bad-field:relayed"),
        ({"sender": agent_sender(5)}, "forged-sender"),
    ]:
        wire = messages.to_wire(good)
        if "relayed" in bad:
            wire[wire_index(Answer, "relayed")] = [list(pair) for pair in bad["relayed"]]
        else:
            wire[wire_index(Answer, "sender")] = bad["sender"]
        with pytest.raises(Rejected) as caught:
            parse(msgpack.packb(wire), Answer, RUN)
        assert caught.value.reason == reason, bad
    with pytest.raises(Rejected) as caught:
        parse(encode(good), Answer, RUN, key_agent=3)
    assert caught.value.reason == "forged-sender"



# ---------------------------------------------------------------- the one path, edge by edge


MANY = settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _plain(value):
    """What msgpack is to pack for a numpy value (a str subclass: its str)."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, str):
        return str(value)
    raise TypeError(f"cannot pack {type(value).__name__}")


def expected_encoding(msg):
    """What encode is to make of ``msg``, by the other msgpack library and the reference: the
    bytes, or the reason it is rejected."""
    try:
        keys.validate_run_id(msg.run)
    except ValueError:
        return "bad-field:run"
    for name, value in zip(fields_of(type(msg)), values(msg)):
        try:
            msgpack.packb(value, default=_plain)
        except (TypeError, ValueError, OverflowError):
            return f"bad-field:{name}"
    payload = msgpack.packb([TAG[type(msg)], *values(msg)], default=_plain)
    return reference_reason(payload, type(msg), msg.run) or payload


def encoding_of(msg):
    """What encode makes of ``msg`` as its receiver takes it: the bytes, or the reason they (or
    ``msg`` itself, where msgpack cannot carry it) are refused."""
    try:
        payload = encode(msg)
        parse(payload, type(msg), msg.run)
    except Rejected as e:
        return e.reason
    return payload


def test_wire_bytes_are_pinned():
    """The exact bytes of protocol version 11 (item order, int / float / bool / binary types)."""
    pinned = {
        obs():  # 20 items: an array 16 header; the world's incarnation last
            "dc0014a66f62732f3131a572756e2d3107a5776f726c6402010692030492090"
            "9c40c000003000500050001000100"  # the neighbours: bin 8 of uint16 (id, x, y), LE
            "01cb3fd0000000000000cb4024000000000000c2c2c2c40090c200",
        obs(parked=pack_ids([5]), updates=pack_updates((7, 2210), (0.5, 10)) + ((b"", b""),),
            world=2):
            "dc0014a66f62732f3131a572756e2d3107a5776f726c6402010692030492090"
            "9c40c000003000500050001000100"
            "01cb3fd0000000000000cb4024000000000000c2c2c2c4020500"
            "9292c4040700a208c410000000000000e03f0000000000002440"  # uint16 and float64, LE
            "92c400c400c202",
        answer(run=RUN, tick=3, episode=0, action=1, relayed=((0, 4), (1, 0))):
            "98a9616e737765722f3131a572756e2d3103a76167656e742f3202000192920004920100",
        intent():  # 10 items: the record, then the order, both empty, then the world's
            "9aa9696e74656e742f3131a572756e2d3107a76167656e742f32020103909000",
        intent(order=(3, 0, 4)):  # the order: the action (3) first, then 0, then 4
            "9aa9696e74656e742f3131a572756e2d3107a76167656e742f32020103909303000400",
        control():
            "95aa636f6e74726f6c2f3131a572756e2d3107a5776f726c64a873687574646f776e",
        control(run="r" * 64, tick=2**40):  # str 8 (as use_bin_type gives) and uint 64
            "95aa636f6e74726f6c2f3131d940" + "72" * 64
            + "cf0000010000000000a5776f726c64a873687574646f776e",
    }
    for msg, hexed in pinned.items():
        assert encode(msg).hex() == hexed
        assert parse(bytes.fromhex(hexed), type(msg), msg.run) == msg
        assert msgpack.unpackb(bytes.fromhex(hexed)) == [TAG[type(msg)], *_as_lists(values(msg))]
    assert msgpack.unpackb(bytes.fromhex(pinned[intent(order=(3, 0, 4))])) == [
        "intent/11", RUN, 7, "agent/2", 2, 1, 3, [], [3, 0, 4], 0]


@given(any_message, st.sampled_from([bytes, bytearray, memoryview, zenoh.ZBytes]))
@FUZZ
def test_every_valid_message_packs_as_msgpack_would_and_comes_back_the_same(msg, form):
    """The bytes of any valid message are those the other msgpack library packs, and parse back,
    from any form of payload, to an equal message of the same types."""
    payload = encode(msg)
    assert payload == expected_encoding(msg) == msgpack.packb(to_wire(msg))
    back = parse(form(payload), type(msg), msg.run, getattr(msg, "agent", None))
    assert repr(back) == repr(msg) and hash(back) == hash(msg)


def test_numpy_values_lists_str_subclasses_and_ints_for_floats_go_on_the_wire_plain():
    plain = encode(obs())
    for msg in (obs(agent=np.int64(2)), obs(position=[3, 4]),
                obs(neighbours=pack_neighbours([[0, 3, 5], (5, 1, 1)])),
                obs(neighbours=pack_neighbours(np.array([[0, 3, 5], [5, 1, 1]]))),
                obs(collided=np.bool_(False)),
                obs(reward_ds=np.float32(0.25)), obs(step=np.uint8(6))):
        assert encode(msg) == plain
    assert encode(answer(relayed=[(0, 4), [5, 0]])) == encode(answer())
    name = type("Name", (str,), {})
    assert encode(intent(run=name(RUN), sender=name("agent/2"))) == encode(intent())
    assert encode(intent(sender=np.str_("agent/2"))) == encode(intent())
    as_int = encode(obs(reward_ca=10))  # an int is packed as an int, and parsed as a float
    assert msgpack.unpackb(as_int)[wire_index(Observation, "reward_ca")] == 10 and as_int != plain
    assert type(parse(as_int, Observation, RUN).reward_ca) is float
    assert parse(as_int, Observation, RUN) == obs()


# Values a field may be given, valid or not, each tried in every field of every kind, both ways.
_EDGES = [
    None, "", "x", "world", "agent/2", "shutdown", "obs/8", "intent/8", "control/8", "answer/8",
    "obs/7", "intent/7", "intent/6", "control/7", "intent/10", "obs/9", "intent/9", "obs/10",
    "intent/11", "obs/11", "x" * messages.MAX_STR_LEN,
    "x" * (messages.MAX_STR_LEN + 1), b"x", b"", bytes(8), bytes(8 * MAX_AGENTS + 1),
    ((b"\x07\x00", bytes(8)),), ((b"\x07", bytes(8)),), ((b"\x07\x00", bytes(7)),),
    ((b"", b""), (b"", b"")), ((bytes(2 * MAX_AGENTS + 2), b""),), ((b"",),),
    0, 1, 2, 4, 5, -1, MAX_GRID - 1, MAX_GRID, MAX_AGENTS - 1, MAX_AGENTS, MAX_TICK - 1, MAX_TICK,
    2**63, 2**64 - 1, -(2**63), True, False, 0.0, -0.0, 1.0, 2.0, 0.25, 1e6, -1e6,
    math.nextafter(1e6, math.inf), -(10**6) - 1, math.nan, math.inf, -math.inf,
    (), [], (1, 2), [1, 2], (1.0, 2), (True, 0), (MAX_GRID, 0), (1, 2, 3), ((1, 2),), ((1, 2, 3),),
    ((2, 0, 0),), ((1, 0, 0), (1, 2, 2)), ((1, 0, 0), (3, 2, 2)), ((1, 4), (3, 4)), ((1, 5),),
    ((1, 4), (1, 0)), ((True, 4),), ([1, 4],), [[1, 4]], ((1, 4, 0),), {"a": 1},
    (3,), (4,), (3, 0), (3, 3), (0, 3), (3, 0, 4), (3, 5), (3, -1), (3, 0, 1, 2, 4),
    (4, 3, 2, 1, 0), (3, 0, 1, 2, 4, 3), (3, 0, 1, 2, 2), (0, 1, 2, 3, 4, 0), [3, 1], (3, 1.0),
]


def _numpy_twin(value):
    """``value`` as a numpy scalar or array, where it has one."""
    if isinstance(value, bool):
        return np.bool_(value)
    if isinstance(value, int) and -(2**63) <= value < 2**63:
        return np.int64(value)
    if isinstance(value, float):
        return np.float32(value) if abs(value) < 1e30 else np.float64(value)
    if isinstance(value, tuple):
        try:
            return np.array(value)
        except ValueError:  # ragged
            return value
    return value


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("msg", [obs(), obs(neighbours=b""), answer(), answer(relayed=()), intent(),
                                 intent(order=(3, 0, 4)), control(), control(run="r" * 64)])
def test_every_edge_value_in_every_field_is_judged_as_the_reference_judges(msg):
    cls, key_agent = type(msg), getattr(msg, "agent", None)
    for name in fields_of(cls):
        for value in _EDGES:
            for form in (value, _numpy_twin(value)):
                changed = replaced(msg, **{name: form})
                assert encoding_of(changed) == expected_encoding(changed), (name, form)
    wire = to_wire(msg)
    arrays = [[*wire, 1], [], wire[:1], wire[:2], wire[:3], dict(zip("vkrtsaexyz", wire))]
    arrays += [wire[:i] + wire[i + 1:] for i in range(len(wire))]
    for i in range(len(wire)):  # the tag too; and the run parsed for that run
        arrays += [[*wire[:i], value, *wire[i + 1:]] for value in _EDGES]
    for changed in arrays:
        run_item = changed[2] if type(changed) is list and len(changed) > 2 else None
        for run in {RUN, run_item} if type(run_item) is str else {RUN}:
            for key in (None, key_agent, 9):
                payload = pack(changed)
                assert outcome_of(payload, cls, run, key) == reference_reason(
                    payload, cls, run, key), (changed, run, key)


def _twins(value) -> list:
    """Values like ``value`` but of other types (numpy too), or just out of range."""
    if isinstance(value, bool):
        return [np.bool_(value), int(value), float(value), not value]
    if isinstance(value, int):
        return [np.int64(value % 2**63), np.uint64(value % 2**64), np.int32(value % 2**31),
                float(value), bool(value % 2), value - 1, value + 1, -value - 1, value * 2**40 + 1]
    if isinstance(value, float):
        return [np.float64(value), np.float32(value), int(value) if math.isfinite(value) else 0,
                -value, value * 1e7 + 1e6 + 1, math.nan, math.inf, -math.inf, True]
    if isinstance(value, str):
        return [value + "x", value[:-1], value * 40, value.encode(), type("S", (str,), {})(value)]
    if isinstance(value, tuple):
        lists = [list(v) if isinstance(v, tuple) else v for v in value]
        return [list(value), lists, _numpy_twin(value), value[:-1], value + value[:1], value * 2,
                value[::-1]]
    return []


_JUNK = [None, "x", b"x", [], {}, {"a": 1}, 1.5, -1, 2**64 - 1, True, "a" * 300]


@st.composite
def _reshaped(draw, value):
    """``value`` in another form, maybe invalid: a twin, junk, or (a tuple) with one item so."""
    if isinstance(value, tuple) and value and draw(st.booleans()):
        items = list(value)
        i = draw(st.integers(0, len(items) - 1))
        items[i] = draw(_reshaped(items[i]))
        return tuple(items)
    return draw(st.sampled_from(_twins(value) + _JUNK))


@st.composite
def odd_messages(draw):
    """A valid message with up to three fields (or items of them) in another form, maybe invalid,
    maybe the agent listed among its neighbours or relayed intents, and maybe (an intent) its order
    or action redrawn (:func:`_redrawn`)."""
    msg = draw(any_message)
    names = list(fields_of(type(msg)))
    changes = {name: draw(_reshaped(getattr(msg, name)))
               for name in draw(st.lists(st.sampled_from(names), max_size=3))}
    changes.update(_redrawn(draw, msg))
    listed = [row[0] for row in unpack_neighbours(msg.neighbours).tolist()] \
        if isinstance(msg, Observation) else [j for j, _ in getattr(msg, "relayed", ())]
    if listed and draw(st.booleans()):
        changes["agent"] = listed[0]
    return replaced(msg, **changes)


@given(odd_messages())
@MANY
def test_fuzz_odd_messages_are_encoded_as_the_reference_expects(msg):
    assert encoding_of(msg) == expected_encoding(msg)


def _packable(value) -> bool:
    try:
        pack(value)
        return True
    except (TypeError, ValueError, OverflowError):
        return False


@st.composite
def odd_payloads(draw):
    """A valid message's wire array with up to three items (or items of them) in another form or
    dropped, maybe an extra item, maybe made a map, maybe the bytes cut or flipped; and a run and
    key to parse with. An intent's order or action maybe redrawn first (:func:`_redrawn`)."""
    msg = draw(any_message)
    wire = _reordered(draw, msg, to_wire(msg))
    for i in draw(st.lists(st.integers(0, len(wire) - 1), max_size=3)):
        if i >= len(wire):
            continue
        if draw(st.integers(0, 4)) == 0:
            del wire[i]
        else:
            value = draw(_reshaped(wire[i]))
            if _packable(value):
                wire[i] = value
    if draw(st.integers(0, 5)) == 0:
        wire.insert(draw(st.integers(0, len(wire))), draw(scalars))
    if draw(st.integers(0, 19)) == 0:
        wire = {str(i): item for i, item in enumerate(wire)}
    payload = pack(wire)
    if draw(st.integers(0, 5)) == 0:
        payload = bytearray(payload)
        payload[draw(st.integers(0, len(payload) - 1))] = draw(st.integers(0, 255))
        payload = bytes(payload[:draw(st.integers(0, len(payload)))])
    form = draw(st.sampled_from([bytes, bytes, bytes, bytearray, memoryview, zenoh.ZBytes]))
    run = draw(st.sampled_from([msg.run, msg.run, "other"]))
    key_agent = draw(st.sampled_from([None, getattr(msg, "agent", None), 3]))
    return form(payload), type(msg), run, key_agent


@given(odd_payloads())
@MANY
def test_fuzz_odd_payloads_are_judged_as_the_reference_judges(case):
    payload, cls, run, key_agent = case
    data = payload.to_bytes() if isinstance(payload, zenoh.ZBytes) else bytes(payload)
    assert outcome_of(payload, cls, run, key_agent) == reference_reason(data, cls, run, key_agent)


def test_a_reward_whose_abs_overflows_is_refused_from_numpy_as_from_the_wire():
    assert encoding_of(obs(reward_ds=np.int64(-2**63))) == "bad-field:reward_ds"  # abs() < 0
    assert reason_of(mutated(obs(), "reward_ds", -2**63), Observation) == "bad-field:reward_ds"


def test_unpackable_values_are_named_by_their_field():
    for name, value in (("tick", 2**64), ("episode", -(2**63) - 1), ("goal", (object(), 1)),
                        ("sender", object()), ("neighbours", ((1, 2, 2**70),))):
        with pytest.raises(Rejected) as rejected:
            encode(obs(**{name: value}))
        assert rejected.value.reason == f"bad-field:{name}", name


# ---------------------------------------------------------------- the declared schema


def test_the_schema_is_the_annotations_of_the_classes():
    annotated = get_type_hints(Observation, include_extras=True)
    hints = {name: repr(annotated[name]) for name in fields_of(Observation)}
    assert {"from_agent", "agent_lists"} <= set(annotated) - set(hints)  # class variables
    assert "Meta(ge=0, lt=1024)" in hints["agent"] and "max_length=6144" in hints["neighbours"]
    assert "le=1000000.0" in hints["reward_ds"] and hints["collided"] == "<class 'bool'>"
    assert Observation.agent_lists == () and Answer.agent_lists == ("relayed",)
    assert [cls.from_agent for cls in KINDS] == [False, True, True, False]
    order = repr(get_type_hints(Intent, include_extras=True)["order"])
    assert "max_length=5" in order and "Meta(ge=0, lt=5)" in order


def test_a_new_kind_is_declared_by_its_class_alone(monkeypatch):
    """Declaring a message is its class: each field one annotated line (here a per-neighbour flag
    and a tuple of planned moves, with a default), checked on the wire by type and range,
    agent-lists by the rules; the header, and the agent it names, come from its base classes."""
    from typing import Annotated, ClassVar

    from msgspec import Meta

    class Plan(messages.AgentMessage, tag=messages.tag("plan")):
        seen: messages.agent_list(messages.Coord, messages.Coord, bool)
        moves: Annotated[tuple[messages.Action, ...], Meta(max_length=3)] = ()

        from_agent: ClassVar[bool] = True
        agent_lists: ClassVar[tuple[str, ...]] = ("seen",)

    decoder, heads, tags = messages.reading((*MESSAGES, Plan))
    monkeypatch.setattr(messages, "_DECODER", decoder)
    monkeypatch.setattr(messages, "_HEADS", heads)
    monkeypatch.setattr(messages, "_TAGS", tags)
    assert Plan(RUN, 7, "agent/2", 2, ()).moves == ()  # a default: calls without it still work
    assert msgpack.unpackb(encode(Plan(RUN, 7, "agent/2", 2, ())))[-1] == []
    good = Plan(RUN, 7, "agent/2", 2, ((0, 1, 1, True), (5, 2, 2, False)), (1, 4))
    payload = encode(good)
    assert msgpack.unpackb(payload) == ["plan/11", RUN, 7, "agent/2", 2,
                                        [[0, 1, 1, True], [5, 2, 2, False]], [1, 4]]
    assert parse(payload, Plan, RUN, key_agent=2) == good
    for change, reason in [
        ({"moves": (1, 2, 3, 4)}, "bad-field:moves"), ({"moves": (5,)}, "bad-field:moves"),
        ({"seen": ((0, 1, 1, 1),)}, "bad-field:seen"),
        ({"seen": ((2, 1, 1, True),)}, "bad-field:seen"),
        ({"seen": ((0, 1, 1, True), (0, 2, 2, True))}, "bad-field:seen"),
        ({"sender": "agent/3"}, "forged-sender"),
    ]:
        wire = to_wire(good)
        name, value = next(iter(change.items()))
        wire[wire_index(Plan, name)] = value
        assert reason_of(pack(wire), Plan, key_agent=2) == reason, change
    assert reason_of(payload, Plan, key_agent=3) == "forged-sender"
    assert reason_of(payload, Intent) == "wrong-kind"


def test_a_bad_item_is_named_by_its_fields_own_decoder():
    """No error text is read: the item a rejection names is the first one its field's decoder
    refuses, and a payload with no bad item is accepted, in any msgpack form of its array."""
    for name, value in (("tick", -1), ("neighbours", [[1, 2, 3], [4, 5, MAX_GRID]]),
                        ("position", [0, "x"]), ("episode_end", None)):
        rejected = messages._rejection(mutated(obs(), name, value), Observation, RUN)
        assert rejected.reason == f"bad-field:{name}"
    assert messages._rejection(encode(obs()), Observation, RUN) is None
    array16 = b"\xdc\x00\x0a" + encode(intent())[1:]  # 10 items, in a longer header than needed
    assert parse(array16, Intent, RUN) == intent()
    assert reason_of(b"\xdc\x00\x0b" + encode(intent())[1:], Intent) == "not-msgpack"


def test_oversize_rejected_before_unpacking(monkeypatch):
    class Boom:
        def decode(self, data):
            raise AssertionError("unpacked an oversized payload")

    monkeypatch.setattr(messages, "_DECODER", Boom())
    monkeypatch.setattr(messages, "_UNTYPED", Boom())
    huge = b"\x00" * (MAX_PAYLOAD_BYTES + 1)
    for form in (bytes, bytearray, memoryview, zenoh.ZBytes):
        assert reason_of(form(huge), Intent) == "oversize"
        assert Inbox(RUN).decode(form(huge), Observation) is None


def test_inbox_counts_an_unexpected_error_and_still_raises_for_a_wrong_class(monkeypatch):
    def broken(msg, key_agent):
        if type(msg) is Intent:
            raise RuntimeError("a bug in a rule")

    payload = encode(intent())
    monkeypatch.setattr(messages, "_check_rules", broken)
    with pytest.raises(RuntimeError):
        parse(payload, Intent, RUN)  # a bug, not bad input: parse does not hide it
    inbox = Inbox(RUN)
    assert inbox.decode(payload, Intent) is None  # but a node's Inbox counts it
    assert inbox.decode(encode(control()), Control) == control()
    assert inbox.rejections == {"decode-error": 1} and inbox.accepted == 1
    with pytest.raises(TypeError, match="not a message class"):
        inbox.decode(b"\xc1", dict)


def test_encode_and_parse_from_many_threads_at_once():
    from concurrent.futures import ThreadPoolExecutor

    msgs = [obs(tick=t, neighbours=pack_neighbours([(0, t % MAX_GRID, 1)])) for t in range(2000)]
    expected = [msgpack.packb(to_wire(m)) for m in msgs]

    def round_trip(m):
        payload = encode(m)
        return payload, parse(payload, Observation, RUN)

    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(round_trip, msgs))
    assert [p for p, _ in results] == expected
    assert [m for _, m in results] == msgs


def test_the_shared_tables_updates_travel_packed_and_a_packing_cut_short_is_refused():
    """Protocol 10: each group of updates is two binaries, its entries as little-endian uint16
    and their values as float64, at most MAX_AGENTS entries a group; a binary whose length is
    not a whole number of them is refused."""
    many = pack_updates(range(MAX_AGENTS + 1), [0.25] * (MAX_AGENTS + 1))
    assert [len(unpack_group(group)[0]) for group in many] == [MAX_AGENTS, 1]
    msg = obs(updates=pack_updates((7, 2210), (0.5, -1e6)))
    assert parse(encode(msg), Observation, RUN) == msg
    entries, values = unpack_group(msg.updates[0])
    assert entries.tolist() == [7, 2210] and values.tolist() == [0.5, -1e6]
    for cut in ((b"\x07", bytes(8)), (b"\x07\x00", bytes(7)), (b"", bytes(9))):
        assert reason_of(encode(obs(updates=(cut,))), Observation) == "bad-field:updates"
