"""Every wire message of the swarm, and the one msgpack codec that encodes and validates them.

On the wire a message is a msgpack array: ``[version, kind tag, run id, tick, sender, ...]``, then
the other fields of its kind in its class's field order. An array, not a map with a short key per
field (protocol version 1), because the codec is on the critical path of the lockstep loop: no keys
to pack, unpack, hash and match, a smaller payload, and one shape to check (exactly as many items as
the kind has fields). The version and the kind lead, so that a message of another version or kind
says so whatever its length.

Each message is a :class:`typing.NamedTuple` whose annotations are its schema: msgspec types with
:class:`msgspec.Meta` bounds (``Count``, ``AgentId``, ``Reward``, ...). :func:`_message` registers a
class under its kind tag and builds one ``msgspec.msgpack.Decoder`` for its whole wire array, which
checks every type and range in C; a few rules between fields (:func:`_rules`) follow in Python.
No source text is generated: the types are the checks.

To add a field, write one annotated line in the class where its item goes in the array (after the
header ``run, tick, sender``, and ``agent`` if the kind names one); with a default, as the last
line, existing constructor calls need no change. For example, a per-neighbour "parked" flag is
``Neighbours = agent_list(Coord, Coord, bool)``, and planned later moves are
``plan: Annotated[tuple[Action, ...], Meta(max_length=8)] = ()`` at the end of ``Intent``. A list
with one entry per agent (:func:`agent_list`) also gets the agent-list rules. Bump
:data:`PROTOCOL_VERSION` whenever the array changes, so that other versions say so.

:func:`parse` checks, in order, and raises :class:`Rejected` with the reason in brackets: bytes
(``not-bytes``); size, before unpacking (``oversize``); msgpack, with no maps and no ext types
anywhere, no string or binary longer than MAX_STR_LEN characters or bytes and no array longer than
MAX_AGENTS items (``not-msgpack``); an array at the top level (``not-array``; a map there is told by
its first byte, whatever follows, so a version-1 message is ``not-array``, never ``not-msgpack``);
the version, if the array has an item (``bad-version``); the kind, if it has two (``wrong-kind``);
exactly the kind's number of items (``wrong-length``); run id (``wrong-run``); each field's type
and range, the first bad one named (``bad-field:<name>``); then the rules between fields: an
agent-list naming an agent twice (``bad-field:<name>``), the sender (``forged-sender``: the world,
or the agent the message is of, on its own key), the message's own agent in one of its
agent-lists (``bad-field:<name>``). Types are strict: a bool is not an int, an int is not a bool;
float fields take ints but must be finite. The decoder and the rules decide; when the decoder
refuses, :func:`_rejection` reads the payload again, untyped, only to name the first rule broken.
:class:`Inbox` turns a rejection into a counted, rate-limited log line and None, and never raises.

:func:`encode` packs a message (numpy scalars and arrays become plain values); it refuses only what
msgpack cannot carry and a bad run id. It does not parse what it made: every receiver parses every
payload anyway (input can be forged), so a malformed message is refused and counted where it
arrives, and the tests check that no node's own message is ever refused there. Parsing on the way
out too cost the world 40 % of its Python at 64 agents (``bench/node_cpu.py``, docs/performance.md).
An int given for a float field goes on the wire as an int, which parses to the same float.
"""

import logging
import re
from collections import Counter
from collections.abc import Callable
from typing import TYPE_CHECKING, Annotated, Literal, NamedTuple, Protocol, get_type_hints

import msgspec
import numpy as np
from msgspec import Meta

from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES
from nnql_swarm.protocol.keys import MAX_AGENTS, MAX_TICK, validate_run_id

PROTOCOL_VERSION = 6
MAX_GRID = 1024
"""Coordinates are 0 .. MAX_GRID - 1 on each axis."""
MAX_PAYLOAD_BYTES = 64 * 1024
"""Larger payloads are rejected unread (an Observation with a resynchronising slice of the
shared table and 64 neighbours is about 27 KB; with 1,000 neighbours, all parked, about 40)."""
MAX_REWARD = 1e6
MAX_STR_LEN = 256

WORLD_SENDER = "world"
CONTROL_SHUTDOWN = "shutdown"
CONTROL_COMMANDS = frozenset({CONTROL_SHUTDOWN})

__all__ = [
    "PROTOCOL_VERSION", "MAX_AGENTS", "MAX_GRID", "MAX_PAYLOAD_BYTES", "WORLD_SENDER",
    "CONTROL_SHUTDOWN", "CONTROL_COMMANDS", "agent_sender", "Observation", "Intent", "Answer",
    "Control", "SCHEMA", "Kind", "Rejected", "encode", "to_wire", "parse", "Inbox",
]


def agent_sender(agent: int) -> str:
    """The sender name of an agent: ``"agent/<id>"``."""
    return f"agent/{agent}"


# ---------------------------------------------------------------- field types

Name = Annotated[str, Meta(max_length=MAX_STR_LEN)]
Count = Annotated[int, Meta(ge=0, lt=MAX_TICK)]
"""Ticks, episodes, steps."""
AgentId = Annotated[int, Meta(ge=0, lt=MAX_AGENTS)]
Action = Annotated[int, Meta(ge=0, lt=N_ACTIONS)]
"""0 .. N_ACTIONS - 1, see protocol.actions."""
Coord = Annotated[int, Meta(ge=0, lt=MAX_GRID)]
Cell = tuple[Coord, Coord]
Reward = Annotated[float, Meta(ge=-MAX_REWARD, le=MAX_REWARD)]
"""Finite: NaN fails both bounds, an infinity one."""
Command = Literal[tuple(sorted(CONTROL_COMMANDS))]


class _AgentList:
    """The mark of an agent-list field: each agent at most once, never the message's own agent."""

    def __repr__(self) -> str:
        return "agent list"


AGENT_LIST = _AgentList()


def agent_list(*rest) -> object:
    """The type of a tuple of ``(agent id, *rest)`` entries, at most one per agent."""
    return Annotated[tuple[tuple[(AgentId, *rest)], ...], Meta(max_length=MAX_AGENTS), AGENT_LIST]


if TYPE_CHECKING:  # what a type checker reads: agent_list's tuples, without msgspec's limits
    Neighbours = tuple[tuple[int, int, int], ...]
    Relayed = tuple[tuple[int, int], ...]
else:
    Neighbours = agent_list(Coord, Coord)
    """``(id, x, y)`` of each visible other agent."""
    Relayed = agent_list(Action)
    """``(id, action)`` of each relayed intent."""
Parked = Annotated[tuple[AgentId, ...], Meta(max_length=MAX_AGENTS)]
"""The ids of the visible others that are parked on their goals."""

MAX_TABLE_ROW = N_STATES * (N_ACTIONS + 1)
"""Above every Q-table row index of a learner (the largest table: offsets x 6 move codes)."""
RecordInts = Annotated[tuple[Annotated[int, Meta(ge=-1, lt=MAX_TABLE_ROW)], ...],
                       Meta(max_length=8 + 2 * MAX_AGENTS)]
"""A learning record's integers (``learning.fields.REC_*``: states, action, and a pair of table
rows per neighbour; the learner checks the layout against its own tables)."""
Record = tuple[RecordInts, tuple[Reward, Reward]]
"""A learning record: its integers and its two rewards."""
Learned = Annotated[tuple[Record, ...], Meta(max_length=1)]
"""The learning record an intent carries (none, or its sender's of this tick)."""
MAX_TABLE_ENTRY = (N_STATES + MAX_TABLE_ROW) * N_ACTIONS
"""Above every entry index of a learner's two tables stacked (``learning.record.record_entries``)."""
TableEntries = Annotated[tuple[Annotated[int, Meta(ge=0, lt=MAX_TABLE_ENTRY)], ...],
                         Meta(max_length=MAX_AGENTS)]
"""Q-values of the shared table by entry index (``learning.record.record_entries``)."""
TableValues = Annotated[tuple[Reward, ...], Meta(max_length=MAX_AGENTS)]
"""Their new values, finite, bounded as a reward is (a Q-value is at most a reward over
1 - gamma)."""
MAX_SYNC_GROUPS = 2
"""Groups of the whole table an observation carries at most beside the tick's, for an agent
being resynchronised (``world.shared_table``)."""
Updates = Annotated[tuple[tuple[TableEntries, TableValues], ...],
                    Meta(max_length=MAX_AGENTS + MAX_SYNC_GROUPS)]
"""The shared table's entries that the last tick's learning records changed, with their new
values: groups of two sequences, the entries and their values, as many of each (the receiver
refuses a group where they differ); the tick's in the order the records were applied (agent-id
order), at most MAX_AGENTS entries a group; then, for an agent being resynchronised, up to
:data:`MAX_SYNC_GROUPS` groups of the whole table's values. Two flat sequences a group, not a
pair per entry: at 64 agents an observation carries about 160 updates, and a pair each cost the
decoder a tuple each (``bench/node_cpu.py``, docs/performance.md)."""


class Rejected(ValueError):
    """A message that failed validation; ``reason`` is short and machine-friendly."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


# ---------------------------------------------------------------- the rules between fields

_AGENT_SENDERS = tuple(map(agent_sender, range(MAX_AGENTS)))
"""The sender of every agent, looked up rather than formatted for each message."""


def _rules(tag: str, fields: tuple[str, ...], from_agent: bool, lists: tuple[int, ...]):
    """The rules between the fields of a kind, as one function ``(items, key_agent)`` that raises
    Rejected: ``items`` its wire array, each field valid, ``key_agent`` the agent of the key it
    came on (or None). ``lists`` are where its agent-lists are in the array."""

    def sent_by_agent(items: tuple, key_agent: int | None) -> None:
        agent = items[5]
        if items[4] != _AGENT_SENDERS[agent]:
            raise Rejected("forged-sender", f"agent {agent}'s {tag} sent by {items[4]!r}")
        if key_agent is not None and agent != key_agent:
            raise Rejected("forged-sender", f"agent {agent}'s {tag} on {key_agent}'s key")

    def sent_by_world(items: tuple, key_agent: int | None) -> None:
        if items[4] != WORLD_SENDER:
            raise Rejected("forged-sender", f"{tag} sent by {items[4]!r}")

    sender_rule = sent_by_agent if from_agent else sent_by_world
    if not lists:
        return sender_rule

    def with_agent_lists(items: tuple, key_agent: int | None) -> None:
        ids_of = []
        for i in lists:
            ids = {entry[0] for entry in items[i]}
            if len(ids) != len(items[i]):
                raise Rejected(f"bad-field:{fields[i - 2]}", "the same agent twice")
            ids_of.append((i, ids))
        sender_rule(items, key_agent)
        for i, ids in ids_of:
            if items[5] in ids:
                raise Rejected(f"bad-field:{fields[i - 2]}", f"agent {items[5]} lists itself")

    return with_agent_lists


# ---------------------------------------------------------------- the registry of kinds

class Kind(NamedTuple):
    """How one message class goes on the wire."""

    tag: str
    fields: tuple[str, ...]  # the class's, in wire order
    head: tuple[int, str]  # the items before the fields: the version and the tag
    decoder: msgspec.msgpack.Decoder  # of its whole wire array
    rules: Callable[[tuple, int | None], None]  # the rules between its fields, see _rules


SCHEMA: dict[type, Kind] = {}
"""Message class -> its :class:`Kind`."""

_HEADER = ("run", "tick", "sender")


def _message(tag: str, *, from_agent: bool):
    """Register a NamedTuple as the message of kind ``tag``, sent by the agent it names (in its
    ``agent`` field, right after the header) or else by the world; its annotations are its
    schema."""
    def register(cls: type) -> type:
        hints = get_type_hints(cls, include_extras=True)
        types = tuple(hints[name] for name in cls._fields)
        lists = tuple(2 + i for i, t in enumerate(types)
                      if AGENT_LIST in getattr(t, "__metadata__", ()))
        if cls._fields[:3] != _HEADER or (from_agent or lists) and cls._fields[3] != "agent":
            raise TypeError(f"{cls.__name__} must start with {_HEADER}, then agent if it names "
                            "one")
        decoder = msgspec.msgpack.Decoder(tuple[(Literal[PROTOCOL_VERSION], Literal[tag], *types)])
        rules = _rules(tag, cls._fields, from_agent, lists)
        SCHEMA[cls] = Kind(tag, cls._fields, (PROTOCOL_VERSION, tag), decoder, rules)
        return cls
    return register


# ---------------------------------------------------------------- the messages

@_message("obs", from_agent=False)
class Observation(NamedTuple):
    """World -> one agent, each tick: where it is, what it sees, how its previous action went."""

    run: Name
    tick: Count
    sender: Name
    agent: AgentId
    episode: Count
    step: Count
    position: Cell
    goal: Cell
    neighbours: Neighbours
    rank: AgentId  # priority this tick, 0 = highest
    reward_ds: Reward  # rewards of the agent's previous action
    reward_ca: Reward
    collided: bool
    arrived: bool
    episode_end: bool
    parked: Parked = ()
    updates: Updates = ()  # where the swarm shares one table
    settled: bool = False  # parked since an earlier tick: the world expects no intent (engine)


@_message("intent", from_agent=True)
class Intent(NamedTuple):
    """Agent -> world and neighbours: its action at this tick (never changed once sent)."""

    run: Name
    tick: Count
    sender: Name
    agent: AgentId
    episode: Count
    action: Action
    record: Learned = ()  # where the swarm shares one table: this tick's learning record


@_message("answer", from_agent=True)
class Answer(NamedTuple):
    """Agent -> a neighbour that asked for its intent: its action at this tick, and the actions
    of the higher-ranked agents it learned while negotiating (relayed: ``(agent, action)``).

    The relayed intents spare the asker from asking each of those agents itself
    (``agent.negotiation``); they are what those agents announced, which never changes.
    """

    run: Name
    tick: Count
    sender: Name
    agent: AgentId
    episode: Count
    action: Action
    relayed: Relayed


@_message("control", from_agent=False)
class Control(NamedTuple):
    """World -> everyone: a command from CONTROL_COMMANDS."""

    run: Name
    tick: Count
    sender: Name
    command: Command


def _kind(cls) -> Kind:
    try:
        return SCHEMA[cls]
    except (KeyError, TypeError):
        raise TypeError(f"not a message class: {cls!r}") from None


# ---------------------------------------------------------------- parsing

_MAP_HEADS = frozenset({*range(0x80, 0x90), 0xDE, 0xDF})
"""The first bytes of a msgpack map (fixmap, map 16, map 32)."""

_UNTYPED = msgspec.msgpack.Decoder()
_PLAIN = (int, float, bool, type(None))
_ITEM = re.compile(r" - at `\$\[(\d+)\]")
"""The top-level item a msgspec ValidationError names: `` - at `$[7]` `` or `` `$[7][0][2]` ``."""


def _foreign(value) -> str | None:
    """What in an untyped decoded payload the wire never carries, or None: a map, an ext type,
    a string or binary over MAX_STR_LEN, an array over MAX_AGENTS items."""
    stack = [value]
    while stack:
        v = stack.pop()
        t = type(v)
        if t is list:
            if len(v) > MAX_AGENTS:
                return f"an array of {len(v)} items"
            stack.extend(v)
        elif t is str or t is bytes:
            if len(v) > MAX_STR_LEN:
                return f"a {t.__name__} of length {len(v)}"
        elif t is dict:
            return "a map"
        elif t not in _PLAIN:
            return f"an ext type ({t.__name__})"
    return None


def _rejection(data: bytes, kind: Kind, run_id: str, error: Exception) -> Rejected:
    """Why the decoder of ``kind`` refused ``data``: the first rule broken, in the order of the
    module docstring (the decoder stops at the first error it meets, which may come later)."""
    if data and data[0] in _MAP_HEADS:
        return Rejected("not-array", "top level is a map")
    try:
        items = _UNTYPED.decode(data)
    except Exception as e:  # malformed, truncated, trailing bytes, bad UTF-8, nested too deep
        return Rejected("not-msgpack", f"{type(e).__name__}: {e}")
    foreign = _foreign(items)
    if foreign:
        return Rejected("not-msgpack", f"{foreign} is not allowed")
    if type(items) is not list:
        return Rejected("not-array", f"top level is {type(items).__name__}")
    if items and (type(items[0]) is not int or items[0] != PROTOCOL_VERSION):
        return Rejected("bad-version", f"expected {PROTOCOL_VERSION}, got {items[0]!r}")
    if len(items) > 1 and items[1] != kind.tag:
        return Rejected("wrong-kind", f"expected {kind.tag!r}, got {items[1]!r}")
    if len(items) != 2 + len(kind.fields):
        return Rejected("wrong-length", f"expected {2 + len(kind.fields)} items, got {len(items)}")
    if items[2] != run_id:
        return Rejected("wrong-run", f"expected {run_id!r}, got {items[2]!r}")
    item = _ITEM.search(str(error))
    if item is None or not 3 <= int(item[1]) < len(items):  # not an error msgspec words so
        return Rejected("decode-error", str(error))
    return Rejected(f"bad-field:{kind.fields[int(item[1]) - 2]}", str(error))


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


_new = tuple.__new__


def parse(payload: bytes, kind: type, run_id: str, key_agent: int | None = None):
    """Decode and validate one message of class ``kind`` for run ``run_id``; raises Rejected.

    ``payload`` is bytes (or bytearray, memoryview, or zenoh ZBytes). ``key_agent`` is the agent id
    parsed from the key an Intent arrived on: the intent must be that agent's own.
    """
    try:
        info = SCHEMA[kind]
    except (KeyError, TypeError):
        raise TypeError(f"not a message class: {kind!r}") from None
    data = payload if type(payload) is bytes else _as_bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise Rejected("oversize", f"{len(data)} bytes")
    try:
        items = info.decoder.decode(data)
    except msgspec.DecodeError as error:  # ValidationError is one too
        raise _rejection(data, info, run_id, error) from None
    if items[2] != run_id:
        raise Rejected("wrong-run", f"expected {run_id!r}, got {items[2]!r}")
    info.rules(items, key_agent)
    return _new(kind, items[2:])  # kind(*items[2:]), without the call


# ---------------------------------------------------------------- encoding

def _plain(value):
    """msgspec's hook for what it cannot pack: numpy scalars and arrays, str subclasses."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, str):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not a message value")


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_plain)


_VALID_RUNS: set[str] = set()
"""The run ids of the messages encoded so far (a few), checked once each."""


def _check_run(run) -> None:
    try:
        validate_run_id(run)
    except ValueError as e:
        raise Rejected("bad-field:run", str(e)) from None
    if len(_VALID_RUNS) >= 64:
        _VALID_RUNS.clear()
    _VALID_RUNS.add(run)


def _unpackable(kind: Kind, msg: tuple) -> str:
    """The first field of ``msg`` msgpack cannot carry (some field could not be packed)."""
    for name, value in zip(kind.fields, msg):
        try:
            _ENCODER.encode(value)
        except (TypeError, ValueError, OverflowError, msgspec.EncodeError):
            return name
    return "?"


def encode(msg) -> bytes:
    """msgpack bytes of a message, unchecked beyond what msgpack can carry (the receiver parses
    them); raises Rejected (a ValueError) for a field msgpack cannot pack or a bad run id."""
    kind = SCHEMA.get(type(msg))
    if kind is None or len(msg) != len(kind.fields):  # the latter only tuple.__new__ can make
        raise TypeError(f"not a message: {msg!r:.100}")
    run = msg[0]
    if type(run) is not str or run not in _VALID_RUNS:
        _check_run(run)
    try:
        return _ENCODER.encode(kind.head + msg)
    except (TypeError, ValueError, OverflowError, msgspec.EncodeError) as error:  # not packable
        raise Rejected(f"bad-field:{_unpackable(kind, msg)}", str(error)) from None


def to_wire(msg) -> list:
    """The validated wire array of a message (what :func:`encode` packs, as plain values)."""
    return list(SCHEMA[type(msg)].decoder.decode(encode(msg)))


# ---------------------------------------------------------------- receiving

class WarningLog(Protocol):
    """Where an :class:`Inbox` logs its rejections: a ``logging.Logger``, or a protocol
    machine's log of effects."""

    def warning(self, message: str, /, *args: object) -> None: ...


class Inbox:
    """The receiving end of one node: decodes payloads, counts and logs rejections, never raises.

    ``rejections`` is a Counter of reasons, ``accepted`` the number of messages decoded. Each reason
    is logged (WARNING) for its first 10 occurrences, then every 1000th, so a flood cannot flood the
    log. Not locked: use it from one thread at a time (the nodes call it under their own lock,
    from Zenoh's callbacks and their main thread).
    """

    LOG_FIRST = 10
    LOG_EVERY = 1000

    def __init__(self, run_id: str, logger: WarningLog | None = None):
        self.run_id = validate_run_id(run_id)
        self.log = logger or logging.getLogger(__name__)
        self.rejections: Counter = Counter()
        self.accepted = 0

    @property
    def total_rejected(self) -> int:
        return sum(self.rejections.values())

    def decode(self, payload, kind: type, key_agent: int | None = None):
        """The message of class ``kind`` in ``payload``, or None (counted, logged) if rejected."""
        try:
            msg = parse(payload, kind, self.run_id, key_agent)
        except Rejected as e:
            return self.reject(e.reason, f"{kind.__name__}: {e.detail}")
        except Exception as e:  # parse raises only Rejected for any payload; this guards the loop
            _kind(kind)  # but a wrong class is a bug in the caller, not bad input: raised
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
