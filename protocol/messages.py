"""Every wire message of the swarm, and the one msgpack codec that encodes and validates them.

On the wire a message is a msgpack map with short keys: ``v`` (protocol version), ``k`` (kind tag),
``r`` (run id), ``t`` (tick), ``s`` (sender), then the fields of its kind; :data:`SCHEMA` is the
only place that maps fields to wire keys.

:func:`parse` checks, in order, and raises :class:`Rejected` with the reason in brackets: bytes
(``not-bytes``); size, before unpacking (``oversize``; it stands in for ``max_buffer_size``, which
``msgpack.unpackb`` lacks); msgpack with strict limits and no ext types (``not-msgpack``); a map
(``not-map``); version (``bad-version``); kind (``wrong-kind``); exactly the expected keys
(``missing-field:<name>``, ``extra-field``); run id (``wrong-run``); each field's type and range
(``bad-field:<name>``); the sender (``forged-sender``). Types are strict: a bool is not an int, an
int is not a bool; float fields take ints but must be finite. :class:`Inbox` turns a rejection
into a counted, rate-limited log line and None, and never raises. :func:`encode` runs the same
checks (accepting numpy scalars and arrays), so a malformed message fails where it is made.

Both first try a fast path, compiled at import from :data:`SCHEMA` (each check has a fast form):
it tests every field inline and answers only for a valid message of plain built-in types; at any
doubt (numpy, lists, an int for a float, anything invalid) it steps aside and the generic checks
decide, so every rejection, its reason and its order are theirs.
"""

import logging
import threading
from collections import Counter
from dataclasses import dataclass
from functools import lru_cache
from operator import attrgetter, itemgetter
from typing import NamedTuple

import msgpack
import numpy as np

from protocol.actions import N_ACTIONS
from protocol.keys import MAX_AGENTS, MAX_TICK, validate_run_id

PROTOCOL_VERSION = 1
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


@dataclass(frozen=True, slots=True)
class Observation:
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


@dataclass(frozen=True, slots=True)
class Intent:
    """Agent -> world and neighbours: its action at this tick (never changed once sent)."""

    run: str
    tick: int
    sender: str
    agent: int
    episode: int
    action: int  # 0 .. N_ACTIONS - 1, see protocol.actions


@dataclass(frozen=True, slots=True)
class Answer:
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


@dataclass(frozen=True, slots=True)
class Control:
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

    check.fast = lambda v: (  # as many distinct ids as entries, counting only valid entries
        f"type({v}) is tuple and len({v}) <= {MAX_AGENTS} and len({v}) == "
        f"len({{item[0] for item in {v} if {_fast_tuple('item', (_agent, *rest))}}})"
    )
    return check


_neighbours = _per_agent("[id, x, y]", _coord, _coord)
_relayed = _per_agent("[id, action]", _action)


class Field(NamedTuple):
    name: str
    wire: str
    check: object


class Kind(NamedTuple):
    tag: str
    fields: tuple[Field, ...]


_HEADER = (Field("run", "r", _str), Field("tick", "t", _count), Field("sender", "s", _str))

SCHEMA: dict[type, Kind] = {
    Observation: Kind("obs", _HEADER + (
        Field("agent", "a", _agent),
        Field("episode", "e", _count),
        Field("step", "n", _count),
        Field("position", "p", _cell),
        Field("goal", "g", _cell),
        Field("neighbours", "nb", _neighbours),
        Field("rank", "rk", _agent),
        Field("reward_ds", "rd", _reward),
        Field("reward_ca", "rc", _reward),
        Field("collided", "c", _bool),
        Field("arrived", "ar", _bool),
        Field("episode_end", "ee", _bool),
    )),
    Intent: Kind("intent", _HEADER + (
        Field("agent", "a", _agent),
        Field("episode", "e", _count),
        Field("action", "x", _action),
    )),
    Answer: Kind("answer", _HEADER + (
        Field("agent", "a", _agent),
        Field("episode", "e", _count),
        Field("action", "x", _action),
        Field("relayed", "rl", _relayed),
    )),
    Control: Kind("control", _HEADER + (
        Field("command", "c", _command),
    )),
}
"""Message class -> its kind tag and its fields (name, wire key, check), in wire order."""

_WIRE_KEYS = {cls: frozenset({"v", "k", *(f.wire for f in k.fields)}) for cls, k in SCHEMA.items()}


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


def _checked(cls: type, values: dict, key_agent: int | None) -> object:
    """Build a message from field values (by name), checking every field, then the sender."""
    out = {}
    for f in SCHEMA[cls].fields:
        try:
            out[f.name] = f.check(values[f.name])
        except (ValueError, TypeError) as e:
            raise Rejected(f"bad-field:{f.name}", str(e)) from None
    return _related(cls(**out), key_agent)


def _generic_to_wire(msg) -> dict:
    """:func:`to_wire` by the generic checks (where the fast path steps aside)."""
    cls = type(msg)
    kind = _schema(cls)
    try:
        validate_run_id(msg.run)
    except ValueError as e:
        raise Rejected("bad-field:run", str(e)) from None
    msg = _checked(cls, {f.name: getattr(msg, f.name) for f in kind.fields}, None)
    wire = {"v": PROTOCOL_VERSION, "k": kind.tag}
    for f in kind.fields:
        wire[f.wire] = getattr(msg, f.name)
    return wire


def to_wire(msg) -> dict:
    """The validated wire map of a message (what :func:`encode` packs); Rejected if invalid."""
    fast = _FAST_TO_WIRE.get(type(msg))
    return (fast and fast(msg)) or _generic_to_wire(msg)


class _PerThread(threading.local):
    def __init__(self):
        self.packer = msgpack.Packer(use_bin_type=True)  # what msgpack.packb makes at each call


_PER_THREAD = _PerThread()


def encode(msg) -> bytes:
    """msgpack bytes of a message; raises Rejected (a ValueError) if the message is invalid."""
    return _PER_THREAD.packer.pack(to_wire(msg))


def _no_ext(code, data):
    raise ValueError(f"ext type {code} not allowed")


def _unpackb(payload: bytes, max_map_len: int, use_list: bool = True):
    """``msgpack.unpackb`` with strict limits (and arrays as tuples if not ``use_list``)."""
    return msgpack.unpackb(
        payload, use_list=use_list, raw=False, strict_map_key=True, ext_hook=_no_ext,
        max_ext_len=0, max_str_len=MAX_STR_LEN, max_bin_len=MAX_STR_LEN,
        max_array_len=MAX_AGENTS, max_map_len=max_map_len,
    )


def _as_bytes(payload) -> bytes:
    if isinstance(payload, bytes):
        return payload
    if isinstance(payload, (bytearray, memoryview)):
        if len(payload) > MAX_PAYLOAD_BYTES:  # a memoryview's len counts items: checked again below
            raise Rejected("oversize", f"{len(payload)} items")
        return bytes(payload)
    if hasattr(payload, "to_bytes") and not isinstance(payload, (int, bool)):  # zenoh.ZBytes
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
        if isinstance(data, bytes):
            return data
    raise Rejected("not-bytes", f"payload of type {type(payload).__name__}")


def _generic_parse(payload, kind: type, run_id: str, key_agent: int | None = None):
    """:func:`parse` by the generic checks (where the fast path steps aside)."""
    schema = _schema(kind)
    payload = _as_bytes(payload)
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise Rejected("oversize", f"{len(payload)} bytes")
    try:
        data = _unpackb(payload, 4 * len(schema.fields))
    except Exception as e:
        raise Rejected("not-msgpack", f"{type(e).__name__}: {e}") from None
    if not isinstance(data, dict):
        raise Rejected("not-map", f"top level is {type(data).__name__}")
    version = data.get("v")
    if type(version) is not int or version != PROTOCOL_VERSION:
        raise Rejected("bad-version", f"expected {PROTOCOL_VERSION}, got {version!r}")
    if data.get("k") != schema.tag:
        raise Rejected("wrong-kind", f"expected {schema.tag!r}, got {data.get('k')!r}")
    if data.keys() != _WIRE_KEYS[kind]:
        for f in schema.fields:
            if f.wire not in data:
                raise Rejected(f"missing-field:{f.name}", f"no key {f.wire!r}")
        raise Rejected("extra-field", f"{len(data.keys() - _WIRE_KEYS[kind])} unexpected keys")
    run = data["r"]
    if type(run) is not str or run != run_id:
        raise Rejected("wrong-run", f"expected {run_id!r}, got {run!r}")
    return _checked(kind, {f.name: data[f.wire] for f in schema.fields}, key_agent)


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
# which test each field inline with the fast form of its check. They answer only for a valid
# message of plain built-in types (numpy and lists go the generic way), and None at any doubt or
# broken rule; the generic functions above then decide, and word the rejection.

@lru_cache(maxsize=64)
def _valid_run_id(run: str) -> bool:
    try:
        validate_run_id(run)
    except ValueError:
        return False
    return True


_FAST_CODEC = """
def fast_codec(cls, wire_values, attributes, setters):
    {setter_names} = setters
    new = object.__new__

    def parse(payload, run_id, key_agent):
        try:
            if type(payload) is not bytes:
                payload = _as_bytes(payload)
            if len(payload) > MAX_PAYLOAD_BYTES:
                return None
            data = _unpackb(payload, {max_map_len}, use_list=False)
            if type(data) is not dict or len(data) != {n_keys}:
                return None
            version, tag, {names} = wire_values(data)  # KeyError unless exactly its keys
            if (type(version) is int and version == PROTOCOL_VERSION and tag == {tag!r}
                    and run == run_id and {test}):
                msg = new(cls)  # what the dataclass's __init__ does, in half the time
                {set_fields}
                return _related(msg, key_agent)
        except Exception:  # any doubt
            pass
        return None

    def to_wire(msg):
        try:
            {names} = attributes(msg)
            if {test} and _valid_run_id(run):
                _related(msg, None)
                return {{"v": PROTOCOL_VERSION, "k": {tag!r}, {wire_map}}}
        except (AttributeError, Rejected):
            pass
        return None

    return parse, to_wire
"""


def _compile_fast_codec(cls: type) -> tuple:
    """``parse(payload, run_id, key_agent)`` and ``to_wire(msg)`` of the fast path of ``cls``."""
    kind = SCHEMA[cls]
    names = [f.name for f in kind.fields]
    source = _FAST_CODEC.format(
        tag=kind.tag, n_keys=2 + len(names), max_map_len=4 * len(names), names=", ".join(names),
        test=" and ".join(f.check.fast(f.name) for f in kind.fields),
        wire_map=", ".join(f"{f.wire!r}: {f.name}" for f in kind.fields),
        setter_names=", ".join(f"set_{name}" for name in names),
        set_fields="; ".join(f"set_{name}(msg, {name})" for name in names),
    )
    namespace = {}
    exec(compile(source, f"<fast codec of {cls.__name__}>", "exec"), globals(), namespace)
    return namespace["fast_codec"](
        cls, itemgetter("v", "k", *(f.wire for f in kind.fields)), attrgetter(*names),
        [getattr(cls, name).__set__ for name in names],  # its slots: all its __init__ sets
    )


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
        _schema(kind)  # a wrong class is a bug in the caller, not bad input: that one raises
        try:
            msg = parse(payload, kind, self.run_id, key_agent)
        except Rejected as e:
            return self.reject(e.reason, f"{kind.__name__}: {e.detail}")
        except Exception as e:  # parse raises only Rejected; this guards the event loop anyway
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
