"""Every wire message of the swarm, and the one msgpack codec that encodes and validates them.

On the wire a message is a msgpack array: ``[version, kind tag, run id, tick, sender, ...]``, then
the other fields of its kind, in the order of :data:`SCHEMA` (its class's field order). An array,
not a map with a short key per field (protocol version 1), because the codec is on the critical
path of the lockstep loop: no keys to pack, unpack, hash and match, a smaller payload, and one
shape to check (exactly as many items as the kind has fields). The version and the kind lead, so
that a message of another version or kind says so whatever its length.

:func:`parse` checks, in order, and raises :class:`Rejected` with the reason in brackets: bytes
(``not-bytes``); size, before unpacking (``oversize``; it stands in for ``max_buffer_size``, which
``msgpack.unpackb`` lacks); msgpack with strict limits, no ext types and no maps anywhere
(``not-msgpack``); an array at the top level (``not-array``; a map there is told by its first byte,
whatever follows, so a version-1 message is ``not-array``, never ``not-msgpack``); the version, if
the array has an item (``bad-version``); the kind, if it has two (``wrong-kind``); exactly the
kind's number of items (``wrong-length``); run id (``wrong-run``); each field's type and range
(``bad-field:<name>``); then the rules between fields: the sender (``forged-sender``), an agent
neither among its own neighbours nor relaying its own intent (``bad-field:<name>``). Types are
strict: a bool is not an int, an int is not a bool; float fields take ints but must be finite.
:class:`Inbox` turns a rejection into a counted, rate-limited log line and None, and never raises.
:func:`encode` runs the same checks (accepting numpy scalars and arrays), so a malformed message
fails where it is made.

Messages are :class:`typing.NamedTuple` classes: immutable, built by one ``tuple.__new__``, read
by unpacking. Both :func:`parse` and :func:`encode` first try a fast path, compiled at import from
:data:`SCHEMA` (each check has a fast form): it tests every field inline and answers only for a
valid message of plain built-in types; at any doubt (numpy, lists, an int for a float, anything
invalid) it steps aside and the generic checks decide, so every rejection, its reason and its
order are theirs.
"""

import logging
import threading
from collections import Counter
from functools import lru_cache
from typing import NamedTuple

import msgpack
import numpy as np

from protocol.actions import N_ACTIONS
from protocol.keys import MAX_AGENTS, MAX_TICK, validate_run_id

PROTOCOL_VERSION = 2
MAX_GRID = 1024
"""Coordinates are 0 .. MAX_GRID - 1 on each axis."""
MAX_PAYLOAD_BYTES = 64 * 1024
"""Larger payloads are rejected unread (the largest valid Observation is about 10 KiB)."""
MAX_REWARD = 1e6
MAX_STR_LEN = 256

WORLD_SENDER = "world"
CONTROL_SHUTDOWN = "shutdown"
CONTROL_COMMANDS = frozenset({CONTROL_SHUTDOWN})

__all__ = [
    "PROTOCOL_VERSION", "MAX_AGENTS", "MAX_GRID", "MAX_PAYLOAD_BYTES", "WORLD_SENDER",
    "CONTROL_SHUTDOWN", "CONTROL_COMMANDS", "agent_sender", "Observation", "Intent", "Answer",
    "Control",
    "SCHEMA", "Rejected", "encode", "to_wire", "parse", "Inbox",
]


def agent_sender(agent: int) -> str:
    """The sender name of an agent: ``"agent/<id>"``."""
    return f"agent/{agent}"


class Observation(NamedTuple):
    """World -> one agent, each tick: where it is, what it sees, how its previous action went."""

    run: str
    tick: int
    sender: str
    agent: int
    episode: int
    step: int
    position: tuple[int, int]
    goal: tuple[int, int]
    neighbours: tuple[tuple[int, int, int], ...]  # (id, x, y) of visible others
    rank: int  # priority this tick, 0 = highest
    reward_ds: float  # rewards of the agent's previous action
    reward_ca: float
    collided: bool
    arrived: bool
    episode_end: bool


class Intent(NamedTuple):
    """Agent -> world and neighbours: its action at this tick (never changed once sent)."""

    run: str
    tick: int
    sender: str
    agent: int
    episode: int
    action: int  # 0 .. N_ACTIONS - 1, see protocol.actions


class Answer(NamedTuple):
    """Agent -> a neighbour that asked for its intent: its action at this tick, and the actions
    of the higher-ranked agents it learned while negotiating (relayed: ``(agent, action)``).

    The relayed intents spare the asker from asking each of those agents itself
    (``agent.negotiation``); they are what those agents announced, which never changes.
    """

    run: str
    tick: int
    sender: str
    agent: int
    episode: int
    action: int
    relayed: tuple[tuple[int, int], ...]


class Control(NamedTuple):
    """World -> everyone: a command from CONTROL_COMMANDS."""

    run: str
    tick: int
    sender: str
    command: str


class Rejected(ValueError):
    """A message that failed validation; ``reason`` is short and machine-friendly."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


# Field checks: a decoded (or to-be-encoded) value in, the normalised value out, or ValueError.
# Each has a fast form for the fast path: ``check.fast(v)``, the source of a test (an ``and`` chain)
# of the expression ``v``, true only where the check would return ``v`` itself or its equal (so:
# exact built-in types, tuples and not lists).

def _int(lo: int, hi: int):
    def check(x):
        if type(x) is not int:
            if not isinstance(x, np.integer):  # bool is not an int here
                raise ValueError(f"expected int, got {type(x).__name__}")
            x = int(x)
        if not lo <= x < hi:
            raise ValueError(f"{x} not in [{lo}, {hi})")
        return x
    check.fast = lambda v: f"type({v}) is int and {lo} <= {v} < {hi}"
    return check


def _bool(x):
    if not isinstance(x, (bool, np.bool_)):
        raise ValueError(f"expected bool, got {type(x).__name__}")
    return bool(x)


_bool.fast = lambda v: f"type({v}) is bool"


def _reward(x):
    if type(x) not in (float, int) and not isinstance(x, (np.integer, np.floating)):
        raise ValueError(f"expected float, got {type(x).__name__}")
    value = float(x)  # before abs(): abs(np.int64(-2**63)) overflows to a negative number
    if not abs(value) <= MAX_REWARD:  # also false for NaN
        raise ValueError(f"{x!r} not finite or beyond {MAX_REWARD:g}")
    return value


_reward.fast = lambda v: f"type({v}) is float and {-MAX_REWARD!r} <= {v} <= {MAX_REWARD!r}"


def _str(x):
    if not isinstance(x, str) or len(x) > MAX_STR_LEN:
        raise ValueError(f"expected str, got {type(x).__name__}")
    return x


_str.fast = lambda v: f"type({v}) is str and len({v}) <= {MAX_STR_LEN}"


def _command(x):
    if _str(x) not in CONTROL_COMMANDS:
        raise ValueError(f"unknown command {x!r}")
    return x


_command.fast = lambda v: f"{_str.fast(v)} and {v} in CONTROL_COMMANDS"


_agent = _int(0, MAX_AGENTS)
_action = _int(0, N_ACTIONS)
_coord = _int(0, MAX_GRID)
_count = _int(0, MAX_TICK)
_SEQ = (list, tuple, np.ndarray)


def _fast_tuple(v: str, checks: tuple) -> str:
    """The fast form of a check that ``v`` is a tuple of ``len(checks)`` values, one a check."""
    each = " and ".join(check.fast(f"{v}[{i}]") for i, check in enumerate(checks))
    return f"type({v}) is tuple and len({v}) == {len(checks)} and {each}"


def _cell(x):
    if not isinstance(x, _SEQ) or len(x) != 2:
        raise ValueError("expected [x, y]")
    return (_coord(x[0]), _coord(x[1]))


_cell.fast = lambda v: _fast_tuple(v, (_coord, _coord))


def _per_agent(what: str, *rest):
    """A check of a list with one ``[agent id, *rest]`` entry per agent (at most MAX_AGENTS)."""
    width = 1 + len(rest)

    def check(x):
        if not isinstance(x, _SEQ) or len(x) > MAX_AGENTS:
            raise ValueError(f"expected a list of at most {MAX_AGENTS} {what}")
        out = []
        for item in x:
            if not isinstance(item, _SEQ) or len(item) != width:
                raise ValueError(f"expected {what}")
            out.append((_agent(item[0]), *(c(v) for c, v in zip(rest, item[1:]))))
        if len({entry[0] for entry in out}) != len(out):
            raise ValueError(f"the same agent twice in {what}")
        return tuple(out)

    def fast(v: str) -> str:  # as many distinct ids as entries, counting only valid entries
        assert v.isidentifier(), v  # the ids are kept in ``<v>_ids``, for the fast form of _related
        return (
            f"type({v}) is tuple and len({v}) <= {MAX_AGENTS} and len({v}) == "
            f"len({v}_ids := {{item[0] for item in {v} if {_fast_tuple('item', (_agent, *rest))}}})"
        )

    check.fast = fast
    return check


_neighbours = _per_agent("[id, x, y]", _coord, _coord)
_relayed = _per_agent("[id, action]", _action)


class Field(NamedTuple):
    name: str
    check: object


class Kind(NamedTuple):
    tag: str
    fields: tuple[Field, ...]


_HEADER = (Field("run", _str), Field("tick", _count), Field("sender", _str))

SCHEMA: dict[type, Kind] = {
    Observation: Kind("obs", _HEADER + (
        Field("agent", _agent),
        Field("episode", _count),
        Field("step", _count),
        Field("position", _cell),
        Field("goal", _cell),
        Field("neighbours", _neighbours),
        Field("rank", _agent),
        Field("reward_ds", _reward),
        Field("reward_ca", _reward),
        Field("collided", _bool),
        Field("arrived", _bool),
        Field("episode_end", _bool),
    )),
    Intent: Kind("intent", _HEADER + (
        Field("agent", _agent),
        Field("episode", _count),
        Field("action", _action),
    )),
    Answer: Kind("answer", _HEADER + (
        Field("agent", _agent),
        Field("episode", _count),
        Field("action", _action),
        Field("relayed", _relayed),
    )),
    Control: Kind("control", _HEADER + (
        Field("command", _command),
    )),
}
"""Message class -> its kind tag and its fields (name, check), in wire order: the class's order."""

_MAX_ARRAY_LEN = max(MAX_AGENTS, 2 + max(len(kind.fields) for kind in SCHEMA.values()))
"""The longest array: a list of one entry per agent, or the top level (version, kind, fields)."""


def _schema(kind: type) -> Kind:
    try:
        return SCHEMA[kind]
    except (KeyError, TypeError):
        raise TypeError(f"not a message class: {kind!r}") from None


_AGENT_SENDERS = tuple(map(agent_sender, range(MAX_AGENTS)))
"""The sender of every agent, looked up rather than formatted for each message."""


def _related(msg, key_agent: int | None):
    """``msg`` if the rules between its (valid) fields hold: its sender, whom its lists name."""
    cls = type(msg)
    if cls is Intent or cls is Answer:
        if msg.sender != _AGENT_SENDERS[msg.agent]:
            raise Rejected("forged-sender", f"intent of agent {msg.agent} sent by {msg.sender!r}")
        if key_agent is not None and msg.agent != key_agent:
            raise Rejected("forged-sender", f"agent {msg.agent}'s intent on {key_agent}'s key")
    elif msg.sender != WORLD_SENDER:
        raise Rejected("forged-sender", f"{cls.__name__} sent by {msg.sender!r}")
    if cls is Observation and any(n[0] == msg.agent for n in msg.neighbours):
        raise Rejected("bad-field:neighbours", "the observing agent is among its neighbours")
    if cls is Answer and any(r[0] == msg.agent for r in msg.relayed):
        raise Rejected("bad-field:relayed", "an agent relays its own intent")
    return msg


_related.fast = {  # true exactly where _related returns the message, given its fields valid (as
    # locals, with ``<list>_ids`` the set of the ids in a list, which the list's fast check binds)
    Observation: "sender == WORLD_SENDER and agent not in neighbours_ids",
    Intent: "sender == _AGENT_SENDERS[agent] and (key_agent is None or key_agent == agent)",
    Answer: "sender == _AGENT_SENDERS[agent] and (key_agent is None or key_agent == agent)"
            " and agent not in relayed_ids",
    Control: "sender == WORLD_SENDER",
}


def _checked(cls: type, values, key_agent: int | None) -> object:
    """Build a message from field values (in SCHEMA order), checking each, then their rules."""
    out = {}
    for f, value in zip(SCHEMA[cls].fields, values, strict=True):
        try:
            out[f.name] = f.check(value)
        except (ValueError, TypeError) as e:
            raise Rejected(f"bad-field:{f.name}", str(e)) from None
    return _related(cls(**out), key_agent)


def _generic_to_wire(msg) -> list:
    """:func:`to_wire` by the generic checks (where the fast path steps aside)."""
    cls = type(msg)
    kind = _schema(cls)
    if len(msg) != len(kind.fields):  # only tuple.__new__ can make one so
        raise TypeError(f"a {cls.__name__} of {len(msg)} fields, not {len(kind.fields)}")
    try:
        validate_run_id(msg.run)
    except ValueError as e:
        raise Rejected("bad-field:run", str(e)) from None
    msg = _checked(cls, [getattr(msg, f.name) for f in kind.fields], None)
    return [PROTOCOL_VERSION, kind.tag, *(getattr(msg, f.name) for f in kind.fields)]


def to_wire(msg) -> list:
    """The validated wire array of a message (what :func:`encode` packs); Rejected if invalid."""
    fast = _FAST_TO_WIRE.get(type(msg))
    return (fast and fast(msg)) or _generic_to_wire(msg)


class _PerThread(threading.local):
    def __init__(self):
        self.packer = msgpack.Packer(use_bin_type=True)  # what msgpack.packb makes at each call


_PER_THREAD = _PerThread()


def encode(msg) -> bytes:
    """msgpack bytes of a message; raises Rejected (a ValueError) if the message is invalid."""
    fast = _FAST_TO_WIRE.get(type(msg))  # to_wire(msg), a call less
    return _PER_THREAD.packer.pack((fast and fast(msg)) or _generic_to_wire(msg))


def _no_ext(code, data):
    raise ValueError(f"ext type {code} not allowed")


def _no_map(obj):
    raise ValueError("map not allowed")  # only an empty one gets here, past max_map_len=0


_UNPACK_KEYWORDS = (
    "raw=False, ext_hook=_no_ext, max_ext_len=0, object_hook=_no_map, max_map_len=0, "
    "max_str_len=MAX_STR_LEN, max_bin_len=MAX_STR_LEN, max_array_len=_MAX_ARRAY_LEN"
)
"""The keywords of every ``msgpack.unpackb`` call, as source: strict limits, no ext types, no maps.
The fast path compiles them into its call: passed as ``**options``, they cost a third of it."""

_UNPACK_OPTIONS = eval(f"dict({_UNPACK_KEYWORDS})")

_MAP_HEADS = frozenset({*range(0x80, 0x90), 0xDE, 0xDF})
"""The first bytes of a msgpack map (fixmap, map 16, map 32)."""


def _unpackb(payload: bytes, use_list: bool = True):
    """``msgpack.unpackb`` with strict limits (and arrays as tuples if not ``use_list``)."""
    return msgpack.unpackb(payload, use_list=use_list, **_UNPACK_OPTIONS)


_VIA_TO_BYTES: set[type] = set()
"""The types of the payloads read with their ``to_bytes()`` (zenoh.ZBytes): the first ones tried."""


def _as_bytes(payload) -> bytes:
    if type(payload) not in _VIA_TO_BYTES:
        if isinstance(payload, bytes):
            return payload
        if isinstance(payload, (bytearray, memoryview)):
            if len(payload) > MAX_PAYLOAD_BYTES:  # a memoryview's len counts items: checked again
                raise Rejected("oversize", f"{len(payload)} items")
            return bytes(payload)
        if not hasattr(payload, "to_bytes") or isinstance(payload, (int, bool)):
            raise Rejected("not-bytes", f"payload of type {type(payload).__name__}")
        _VIA_TO_BYTES.add(type(payload))  # a zenoh.ZBytes: and so will be all of that type
    try:
        size = len(payload)
    except Exception:
        size = 0
    if size > MAX_PAYLOAD_BYTES:
        raise Rejected("oversize", f"{size} bytes")
    try:
        data = payload.to_bytes()
    except Exception as e:
        raise Rejected("not-bytes", f"to_bytes() failed: {type(e).__name__}") from None
    if not isinstance(data, bytes):
        raise Rejected("not-bytes", f"to_bytes() gave a {type(data).__name__}")
    return data


def _generic_parse(payload, kind: type, run_id: str, key_agent: int | None = None):
    """:func:`parse` by the generic checks (where the fast path steps aside)."""
    schema = _schema(kind)
    payload = _as_bytes(payload)
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise Rejected("oversize", f"{len(payload)} bytes")
    try:
        data = _unpackb(payload)
    except Exception as e:
        if payload and payload[0] in _MAP_HEADS:  # the top level is a map, whatever follows
            raise Rejected("not-array", "top level is a map") from None
        raise Rejected("not-msgpack", f"{type(e).__name__}: {e}") from None
    if type(data) is not list:
        raise Rejected("not-array", f"top level is {type(data).__name__}")
    if data:
        version = data[0]
        if type(version) is not int or version != PROTOCOL_VERSION:
            raise Rejected("bad-version", f"expected {PROTOCOL_VERSION}, got {version!r}")
    if len(data) > 1 and data[1] != schema.tag:
        raise Rejected("wrong-kind", f"expected {schema.tag!r}, got {data[1]!r}")
    if len(data) != 2 + len(schema.fields):
        raise Rejected("wrong-length", f"expected {2 + len(schema.fields)} items, got {len(data)}")
    run = data[2]
    if type(run) is not str or run != run_id:
        raise Rejected("wrong-run", f"expected {run_id!r}, got {run!r}")
    return _checked(kind, data[2:], key_agent)


def parse(payload: bytes, kind: type, run_id: str, key_agent: int | None = None):
    """Decode and validate one message of class ``kind`` for run ``run_id``; raises Rejected.

    ``payload`` is bytes (or bytearray, memoryview, or zenoh ZBytes). ``key_agent`` is the agent id
    parsed from the key an Intent arrived on: the intent must be that agent's own.
    """
    try:
        msg = _FAST_PARSE[kind](payload, run_id, key_agent)
    except (KeyError, TypeError):  # not a message class: the generic path raises the TypeError
        msg = None
    return msg or _generic_parse(payload, kind, run_id, key_agent)


# The fast path: for each message class, a parser and an encoder compiled from its SCHEMA entry,
# which test each field inline with the fast form of its check, then the rules between fields
# with the fast form of _related. They answer only for a valid message of plain built-in types
# (numpy and lists go the generic way), and None at any doubt or broken rule; the generic
# functions above then decide, and word the rejection. A message is a tuple of its fields in
# wire order, so the encoder unpacks it, and the parser builds it from a slice of the array.

@lru_cache(maxsize=64)
def _valid_run_id(run: str) -> bool:
    try:
        validate_run_id(run)
    except ValueError:
        return False
    return True


_FAST_CODEC = """
def fast_codec(cls):
    new = tuple.__new__

    def parse(payload, run_id, key_agent):
        try:
            if type(payload) is not bytes:
                payload = _as_bytes(payload)
            if len(payload) > MAX_PAYLOAD_BYTES:
                return None
            data = msgpack.unpackb(payload, use_list=False, {unpack_keywords})  # arrays as tuples
            if type(data) is tuple and len(data) == {n_items}:
                version, tag, {names} = data
                if (type(version) is int and version == PROTOCOL_VERSION and tag == {tag!r}
                        and run == run_id and {test} and {related}):
                    return new(cls, data[2:])  # what cls(...) does, without its arguments
        except Exception:  # any doubt
            pass
        return None

    def to_wire(msg):
        key_agent = None
        try:
            {names} = msg
        except ValueError:  # a message of the wrong length: only tuple.__new__ makes one
            return None
        if {test} and _valid_run_id(run) and {related}:
            return [PROTOCOL_VERSION, {tag!r}, {names}]
        return None

    return parse, to_wire
"""


def _compile_fast_codec(cls: type) -> tuple:
    """``parse(payload, run_id, key_agent)`` and ``to_wire(msg)`` of the fast path of ``cls``."""
    kind = SCHEMA[cls]
    names = tuple(f.name for f in kind.fields)
    if names != cls._fields:  # the fast path reads and builds a message as the tuple on the wire
        raise TypeError(f"{cls.__name__}'s fields are not those of its SCHEMA, in order")
    source = _FAST_CODEC.format(
        tag=kind.tag, n_items=2 + len(names), names=", ".join(names),
        test=" and ".join(f.check.fast(f.name) for f in kind.fields), related=_related.fast[cls],
        unpack_keywords=_UNPACK_KEYWORDS,
    )
    namespace = {}
    exec(compile(source, f"<fast codec of {cls.__name__}>", "exec"), globals(), namespace)
    return namespace["fast_codec"](cls)


_FAST_PARSE, _FAST_TO_WIRE = {}, {}
for _cls in SCHEMA:
    _FAST_PARSE[_cls], _FAST_TO_WIRE[_cls] = _compile_fast_codec(_cls)


class Inbox:
    """The receiving end of one node: decodes payloads, counts and logs rejections, never raises.

    ``rejections`` is a Counter of reasons, ``accepted`` the number of messages decoded. Each reason
    is logged (WARNING) for its first 10 occurrences, then every 1000th, so a flood cannot flood the
    log. Not locked: use it from one thread at a time (the nodes call it under their own lock,
    from Zenoh's callbacks and their main thread).
    """

    LOG_FIRST = 10
    LOG_EVERY = 1000

    def __init__(self, run_id: str, logger: logging.Logger | None = None):
        self.run_id = validate_run_id(run_id)
        self.log = logger or logging.getLogger(__name__)
        self.rejections: Counter = Counter()
        self.accepted = 0

    @property
    def total_rejected(self) -> int:
        return sum(self.rejections.values())

    def decode(self, payload, kind: type, key_agent: int | None = None):
        """The message of class ``kind`` in ``payload``, or None (counted, logged) if rejected."""
        try:  # what parse() does, with two calls fewer: the fast path (it never raises), then
            # the generic checks
            fast = _FAST_PARSE[kind]
        except (KeyError, TypeError):  # a wrong class is a bug in the caller, not bad input
            raise TypeError(f"not a message class: {kind!r}") from None
        msg = fast(payload, self.run_id, key_agent)
        if msg is None:
            try:
                msg = _generic_parse(payload, kind, self.run_id, key_agent)
            except Rejected as e:
                return self.reject(e.reason, f"{kind.__name__}: {e.detail}")
            except Exception as e:  # it raises only Rejected; this guards the event loop anyway
                return self.reject("decode-error", f"{kind.__name__}: {type(e).__name__}: {e}")
        self.accepted += 1
        return msg

    def reject(self, reason: str, detail: str = "") -> None:
        """Count and (rate-limited) log a rejection decided by the caller, e.g. "stale-tick"."""
        self.rejections[reason] += 1
        n = self.rejections[reason]
        if n <= self.LOG_FIRST or n % self.LOG_EVERY == 0:
            self.log.warning(
                "run %s: rejected message (%s) #%d: %.200s%s", self.run_id, reason, n, detail,
                f" (from now on every {self.LOG_EVERY}th)" if n == self.LOG_FIRST else "",
            )
        return None
