"""Every wire message of the swarm, and the one msgpack codec that encodes and validates them.

Each message is a frozen, tagged, array-like :class:`msgspec.Struct`: on the wire a msgpack array
``[tag, run, tick, sender, ...]``, then the other fields of its kind in its class's order. The tag
names the kind and the protocol version at once (``"intent/7"``), so that a message of another
version or kind says so in its first item, whatever its length. An array, not a map: no keys to
pack, unpack and match on the critical path of the lockstep loop, and one shape to check. The
annotations are the schema (msgspec types with :class:`msgspec.Meta` bounds: ``Count``,
``AgentId``, ``Reward``, ...), checked in C by one decoder of the union of every kind, which tells
them apart by their tag; the rules between fields (:func:`_check_rules`) follow in Python.

To add a field, write one annotated line in the class where its item goes in the array; with a
default, as the last line, existing constructor calls need no change (the tick of each relayed
intent: ``Relayed = agent_list(Action, Count)``; planned moves: ``plan:
Annotated[tuple[Action, ...], Meta(max_length=8)] = ()`` at the end of ``Intent``). A field of one
entry per agent (:func:`agent_list`) is named in its class's ``agent_lists``. A new kind is a
subclass of :class:`Message` (of :class:`AgentMessage` if it names an agent) with its own
:func:`tag`, listed in :data:`MESSAGES`. Bump :data:`PROTOCOL_VERSION` whenever the array changes.

:func:`parse` checks, in order, and raises :class:`Rejected` with the reason in brackets: bytes
(``not-bytes``); size, before unpacking (``oversize``); msgpack, with no maps and no ext types
anywhere, no string longer than MAX_STR_LEN, no binary longer than MAX_BIN_LEN and no array longer
than MAX_AGENTS items (``not-msgpack``); an array at the top level (``not-array``; a map there is
told by its first byte); the first item, if any, a tag of this version (``bad-version``) and of the
kind expected (``wrong-kind``); exactly the kind's number of items (``wrong-length``); run id
(``wrong-run``); each field's type and range, the first bad one named (``bad-field:<name>``); then
the rules between fields: an agent-list naming an agent twice (``bad-field:<name>``), the sender
(``forged-sender``: the world, or the agent the message is of, on its own key), a packing cut
short (an observation's neighbours, parked ids or shared table's updates: ``bad-field:<name>``),
an intent's order, the message's own agent in one of its agent-lists (``bad-field:<name>``). Types are strict: a bool is not an int, an int is not a bool;
float fields take ints but must be finite. The decoder and the rules decide; when the decoder
refuses, :func:`_rejection` reads the payload again, untyped, and each item with its field's own
decoder, only to name the first rule broken. :class:`Inbox` turns a rejection into a counted,
rate-limited log line and None, and never raises.

:func:`encode` packs a message (numpy scalars and arrays become plain values); it refuses only what
msgpack cannot carry and a bad run id. It does not parse what it made: every receiver parses every
payload (input can be forged), so a malformed message is refused and counted where it arrives, and
the tests check that no node's own message ever is. An int given for a float field goes on the
wire as an int, which parses to the same float.
"""

import functools
import types
from typing import (
    TYPE_CHECKING, Annotated, ClassVar, Literal, Union, get_args, get_type_hints,
)

import msgspec
import numpy as np
from msgspec import Meta

from nnql_swarm.protocol.actions import N_ACTIONS, N_STATES
from nnql_swarm.protocol.keys import MAX_AGENTS, MAX_TICK, validate_run_id

PROTOCOL_VERSION = 11
"""11: an observation's neighbours and parked ids packed (:data:`Neighbours`, :data:`Parked`);
10: the shared table's updates packed (:data:`Updates`)."""
MAX_GRID = 1024
"""Coordinates are 0 .. MAX_GRID - 1 on each axis."""
MAX_PAYLOAD_BYTES = 64 * 1024
"""Larger payloads are rejected unread (an Observation with a resynchronising slice of the
shared table and 64 neighbours is about 27 KB; with 1,000 neighbours, all parked, about 40)."""
MAX_REWARD = 1e6
MAX_STR_LEN = 256

WORLD_SENDER = "world"
Command = Literal["shutdown"]
CONTROL_SHUTDOWN: Command = "shutdown"
CONTROL_COMMANDS = frozenset(get_args(Command))
"""The commands of a :class:`Control`: every value its ``command`` field may take."""


def agent_sender(agent: int) -> str:
    """The sender name of an agent: ``"agent/<id>"``."""
    return f"agent/{agent}"


def tag(kind: str) -> str:
    """The wire tag of a message kind in this protocol version: ``"<kind>/<version>"``."""
    return f"{kind}/{PROTOCOL_VERSION}"


# ---------------------------------------------------------------- field types

Name = Annotated[str, Meta(max_length=MAX_STR_LEN)]
Count = Annotated[int, Meta(ge=0, lt=MAX_TICK)]
"""Ticks, episodes, steps."""
AgentId = Annotated[int, Meta(ge=0, lt=MAX_AGENTS)]
Action = Annotated[int, Meta(ge=0, lt=N_ACTIONS)]
Order = Annotated[tuple[Action, ...], Meta(max_length=N_ACTIONS)]
"""Moves in an order of preference, each at most once (:func:`_check_rules`)."""
"""0 .. N_ACTIONS - 1, see protocol.actions."""
Coord = Annotated[int, Meta(ge=0, lt=MAX_GRID)]
Cell = tuple[Coord, Coord]
Reward = Annotated[float, Meta(ge=-MAX_REWARD, le=MAX_REWARD)]
"""Finite: NaN fails both bounds, an infinity one."""


def agent_list(*rest) -> object:
    """The type of a tuple of ``(agent id, *rest)`` entries, at most one per agent (name the field
    in its class's ``agent_lists``)."""
    # tuple[...] of types known at run time, in a form a type checker reads as a value
    entry = types.GenericAlias(tuple, (AgentId, *rest))
    return Annotated[types.GenericAlias(tuple, (entry, ...)), Meta(max_length=MAX_AGENTS)]


if TYPE_CHECKING:  # what a type checker reads: agent_list's tuples, without msgspec's limits
    Relayed = tuple[tuple[int, int], ...]
else:
    Relayed = agent_list(Action)
    """``(id, action)`` of each relayed intent."""
CELL_TYPE = np.dtype("<u2")
"""How an observation packs its neighbours ``(id, x, y)`` and parked ids: little-endian unsigned
16-bit integers (every agent id is below MAX_AGENTS, every coordinate below MAX_GRID)."""
assert max(MAX_AGENTS, MAX_GRID) <= np.iinfo(CELL_TYPE).max + 1, "an id and a cell must fit"
NEIGHBOUR_ITEMS = 3
"""A neighbour's integers: its id, then its cell's ``x`` and ``y``."""
Neighbours = Annotated[bytes, Meta(max_length=NEIGHBOUR_ITEMS * CELL_TYPE.itemsize * MAX_AGENTS)]
"""The visible other agents, ``(id, x, y)`` each, in id order, packed (:func:`pack_neighbours`).
Packed, not a msgpack array of arrays: an observation of 64 agents carries some 24, which every
agent decoded into as many Python tuples and made an array again for its kernels. The codec
checks that the packing is whole (``bad-field:neighbours``); the receiver's plan checks that
each is one of the run's agents on its grid, none twice and not the receiver itself
(``learning.plan.fits_run``), before any compiled kernel reads them."""
Parked = Annotated[bytes, Meta(max_length=CELL_TYPE.itemsize * MAX_AGENTS)]
"""The ids of the visible others that are parked on their goals, packed (:func:`pack_ids`); the
receiver's plan checks each is one of the run's agents."""

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
ENTRY_TYPE, VALUE_TYPE = np.dtype("<u2"), np.dtype("<f8")
"""How a group of the shared table's updates packs its entries and their values: little-endian
unsigned 16-bit integers (every entry index is below :data:`MAX_TABLE_ENTRY`) and IEEE 754
doubles, the values exactly as the world's table holds them."""
assert MAX_TABLE_ENTRY <= np.iinfo(ENTRY_TYPE).max + 1, "an entry index must fit its packing"
TableEntries = Annotated[bytes, Meta(max_length=ENTRY_TYPE.itemsize * MAX_AGENTS)]
"""At most MAX_AGENTS entry indices of the shared table (``learning.record.record_entries``),
packed as :data:`ENTRY_TYPE`."""
TableValues = Annotated[bytes, Meta(max_length=VALUE_TYPE.itemsize * MAX_AGENTS)]
"""Their new values, packed as :data:`VALUE_TYPE`; the receiver writes only those finite and
bounded as a reward is (a Q-value is at most a reward / (1 - gamma)):
``learning.record.write_entries``."""
MAX_BIN_LEN = VALUE_TYPE.itemsize * MAX_AGENTS
"""The longest binary the wire carries (a group's values)."""
MAX_SYNC_GROUPS = 2
"""Groups of the whole table an observation carries at most beside the tick's, for an agent
being resynchronised (``world.shared_table``)."""
Updates = Annotated[tuple[tuple[TableEntries, TableValues], ...],
                    Meta(max_length=MAX_AGENTS + MAX_SYNC_GROUPS)]
"""The shared table's entries that the last tick's learning records changed, with their new
values: groups of two packed sequences (:func:`pack_updates`), the entries and their values, as
many of each (the receiver refuses a group where they differ); the tick's in the order the
records were applied (agent-id order), at most MAX_AGENTS entries a group; then, for an agent
being resynchronised, up to :data:`MAX_SYNC_GROUPS` groups of the whole table's values. Packed,
not a msgpack array of numbers: an observation of 64 agents carries some 150 entries, which an
array made every agent decode into as many Python numbers, and the world encode for every agent.
The codec checks that each packing is whole (``bad-field:updates``); the receiver, which writes
the values in one compiled loop, checks each entry and value as it writes it."""


def pack_updates(entries, values) -> tuple[tuple[bytes, bytes], ...]:
    """Entries and their values (sequences or arrays of as many) as update groups of at most
    MAX_AGENTS entries each."""
    entries = np.asarray(entries, dtype=ENTRY_TYPE)
    values = np.asarray(values, dtype=VALUE_TYPE)
    return tuple((entries[k:k + MAX_AGENTS].tobytes(), values[k:k + MAX_AGENTS].tobytes())
                 for k in range(0, len(entries), MAX_AGENTS))


def pack_neighbours(neighbours) -> bytes:
    """Neighbours ``(id, x, y)`` (a sequence of triples, or an array ``(k, 3)``) as the wire
    carries them."""
    return np.asarray(neighbours, dtype=CELL_TYPE).tobytes()


def pack_ids(ids) -> bytes:
    """Agent ids (a sequence, or an array) as the wire carries them."""
    return np.asarray(ids, dtype=CELL_TYPE).tobytes()


def unpack_neighbours(packed: bytes) -> np.ndarray:
    """Packed neighbours as a (read-only) array ``(k, 3)`` of ``(id, x, y)``, without copying;
    the packing must be whole (the codec checks it)."""
    return np.frombuffer(packed, CELL_TYPE).reshape(-1, NEIGHBOUR_ITEMS)


def unpack_ids(packed: bytes) -> np.ndarray:
    """Packed agent ids as a (read-only) array, without copying."""
    return np.frombuffer(packed, CELL_TYPE)


def unpack_group(group: tuple[bytes, bytes]) -> tuple[np.ndarray, np.ndarray]:
    """An update group's entries and values as (read-only) arrays, without copying; may differ
    in length where the group was forged."""
    return np.frombuffer(group[0], ENTRY_TYPE), np.frombuffer(group[1], VALUE_TYPE)


class Rejected(ValueError):
    """A message that failed validation; ``reason`` is short and machine-friendly."""

    def __init__(self, reason: str, detail: str = ""):
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


# ---------------------------------------------------------------- the messages

class Message(msgspec.Struct, array_like=True, frozen=True, forbid_unknown_fields=True, gc=False):
    """What every message starts with. ``from_agent``: sent by the agent it names, else by the
    world; ``agent_lists``: its fields of one entry per agent (:func:`agent_list`)."""

    run: Name
    tick: Count
    sender: Name

    from_agent: ClassVar[bool] = False
    agent_lists: ClassVar[tuple[str, ...]] = ()


class AgentMessage(Message, frozen=True):
    """A message of one agent: it names it right after the header."""

    agent: AgentId


class Observation(AgentMessage, tag=tag("obs"), frozen=True):
    """World -> one agent, each tick: where it is, what it sees, how its previous action went."""

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
    parked: Parked = b""
    updates: Updates = ()  # where the swarm shares one table
    settled: bool = False  # parked since an earlier tick: the world expects no intent (engine)
    world: Count = 0
    """The world's incarnation (``transport.runfiles.next_incarnation``: one more each time a
    run's world starts): an intent names the one it was decided for, so that a world started
    again takes no intent decided for the world before it."""


class Intent(AgentMessage, tag=tag("intent"), frozen=True):
    """Agent -> world and neighbours: its action at this tick (never changed once sent) and,
    under ``--arbitration pibt``, its moves in its order of preference (``order``: the action
    first, each move once; ``world.pibt``)."""

    episode: Count
    action: Action
    record: Learned = ()  # where the swarm shares one table: this tick's learning record
    order: Order = ()
    world: Count = 0  # the incarnation of the world whose observation it was decided on

    from_agent = True


class Answer(AgentMessage, tag=tag("answer"), frozen=True):
    """Agent -> a neighbour that asked for its intent: its action at this tick, and the actions
    of the higher-ranked agents it learned while negotiating (relayed: ``(agent, action)``).

    The relayed intents spare the asker from asking each of those agents itself
    (``agent.negotiation``); they are what those agents announced, which never changes.
    """

    episode: Count
    action: Action
    relayed: Relayed

    from_agent = True
    agent_lists = ("relayed",)


class Control(Message, tag=tag("control"), frozen=True):
    """World -> everyone: a command from CONTROL_COMMANDS."""

    command: Command


MESSAGES = (Observation, Intent, Answer, Control)


def _head(cls: type[Message]) -> bytes:
    """The bytes every message of ``cls`` starts with: its array's header, then its tag."""
    items = 1 + len(cls.__struct_fields__)
    header = bytes([0x90 + items]) if items < 16 else b"\xdc" + items.to_bytes(2, "big")
    return header + msgspec.msgpack.encode(cls.__struct_config__.tag)


def reading(kinds: tuple[type[Message], ...]):
    """How the codec reads ``kinds``: one decoder of them all (the tag, the first item, says
    which), how each kind's payloads start as :func:`encode` writes them (its length and tag at
    once), and each tag's kind."""
    return (msgspec.msgpack.Decoder(Union[kinds]), {cls: _head(cls) for cls in kinds},
            {cls.__struct_config__.tag: cls for cls in kinds})


_DECODER, _HEADS, _TAGS = reading(MESSAGES)


# ---------------------------------------------------------------- the rules between fields

_AGENT_SENDERS = tuple(map(agent_sender, range(MAX_AGENTS)))  # looked up, not formatted


def _check_rules(msg: Message, key_agent: int | None) -> None:
    """The rules between the fields of a message whose every field is valid; ``key_agent`` is
    the agent of the key it came on (or None). Raises Rejected."""
    cls = type(msg)
    agent = msg.agent if isinstance(msg, AgentMessage) else None
    lists = cls.agent_lists
    if lists:
        ids_of = []
        for name in lists:
            entries = getattr(msg, name)
            ids = {entry[0] for entry in entries}
            if len(ids) != len(entries):
                raise Rejected(f"bad-field:{name}", "the same agent twice")
            ids_of.append((name, ids))
    if cls.from_agent:
        assert agent is not None  # the kinds agents send are AgentMessage's
        if msg.sender != _AGENT_SENDERS[agent]:
            raise Rejected("forged-sender", f"agent {agent}'s {cls.__name__} sent by "
                                            f"{msg.sender!r}")
        if key_agent is not None and agent != key_agent:
            raise Rejected("forged-sender", f"agent {agent}'s {cls.__name__} on {key_agent}'s "
                                            "key")
    elif msg.sender != WORLD_SENDER:
        raise Rejected("forged-sender", f"{cls.__name__} sent by {msg.sender!r}")
    if isinstance(msg, Observation):
        if len(msg.neighbours) % (NEIGHBOUR_ITEMS * CELL_TYPE.itemsize):
            raise Rejected("bad-field:neighbours", "a packing cut short")
        if len(msg.parked) % CELL_TYPE.itemsize:
            raise Rejected("bad-field:parked", "a packing cut short")
        for entries, values in msg.updates:
            if len(entries) % ENTRY_TYPE.itemsize or len(values) % VALUE_TYPE.itemsize:
                raise Rejected("bad-field:updates", "a packing cut short")
    if isinstance(msg, Intent) and msg.order and (
            msg.order[0] != msg.action or len(set(msg.order)) != len(msg.order)):
        raise Rejected("bad-field:order", "not the action first, each move once")
    for name, ids in ids_of if lists else ():
        if agent in ids:
            raise Rejected(f"bad-field:{name}", f"agent {agent} lists itself")


# ---------------------------------------------------------------- parsing

_MAP_HEADS = frozenset({*range(0x80, 0x90), 0xDE, 0xDF})
"""The first bytes of a msgpack map (fixmap, map 16, map 32)."""

_UNTYPED = msgspec.msgpack.Decoder()
_PLAIN = (int, float, bool, type(None))


def _foreign(value) -> str | None:
    """What in an untyped decoded payload the wire never carries, or None: a map, an ext type,
    a string over MAX_STR_LEN, a binary over MAX_BIN_LEN, an array over MAX_AGENTS items."""
    stack = [value]
    while stack:
        v = stack.pop()
        t = type(v)
        if t is list:
            if len(v) > MAX_AGENTS:
                return f"an array of {len(v)} items"
            stack.extend(v)
        elif t is str or t is bytes:
            if len(v) > (MAX_STR_LEN if t is str else MAX_BIN_LEN):
                return f"a {t.__name__} of length {len(v)}"
        elif t is dict:
            return "a map"
        elif t not in _PLAIN:
            return f"an ext type ({t.__name__})"
    return None


@functools.cache
def _field_decoders(cls: type[Message]) -> tuple[tuple[str, msgspec.msgpack.Decoder], ...]:
    """A decoder of each field of ``cls`` alone, in wire order: what names a bad item."""
    hints = get_type_hints(cls, include_extras=True)
    return tuple((name, msgspec.msgpack.Decoder(hints[name])) for name in cls.__struct_fields__)


def _rejection(data: bytes, kind: type[Message], run_id: str) -> Rejected | None:
    """The first rule ``data`` breaks as a message of ``kind``, in the order of the module
    docstring, read untyped and item by item; None if its items break none."""
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
    expected = kind.__struct_config__.tag
    if items and (type(items[0]) is not str or items[0] not in _TAGS):
        return Rejected("bad-version", f"expected {expected!r}, got {items[0]!r}")
    if items and items[0] != expected:
        return Rejected("wrong-kind", f"expected {expected!r}, got {items[0]!r}")
    fields = _field_decoders(kind)
    if len(items) != 1 + len(fields):
        return Rejected("wrong-length", f"expected {1 + len(fields)} items, got {len(items)}")
    if items[1] != run_id:
        return Rejected("wrong-run", f"expected {run_id!r}, got {items[1]!r}")
    for (name, decoder), item in zip(fields, items[1:]):
        try:
            decoder.decode(_ENCODER.encode(item))
        except msgspec.ValidationError as e:
            return Rejected(f"bad-field:{name}", str(e))
    return None


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


def parse(payload: bytes, kind: type[Message], run_id: str, key_agent: int | None = None):
    """Decode and validate one message of class ``kind`` for run ``run_id``; raises Rejected.

    ``payload`` is bytes (or bytearray, memoryview, or zenoh ZBytes). ``key_agent`` is the agent id
    parsed from the key an Intent arrived on: the intent must be that agent's own.
    """
    try:
        head = _HEADS[kind]
    except (KeyError, TypeError):
        raise TypeError(f"not a message class: {kind!r}") from None
    data = payload if type(payload) is bytes else _as_bytes(payload)
    if len(data) > MAX_PAYLOAD_BYTES:
        raise Rejected("oversize", f"{len(data)} bytes")
    try:
        msg = _DECODER.decode(data)
    except msgspec.DecodeError:  # ValidationError is one too
        raise _rejection(data, kind, run_id) or Rejected("decode-error", "") from None
    if type(msg) is not kind or not data.startswith(head):  # another kind, or another length
        rejected = _rejection(data, kind, run_id)  # (or a valid one in a longer msgpack form)
        if rejected is not None:
            raise rejected
    if msg.run != run_id:
        raise Rejected("wrong-run", f"expected {run_id!r}, got {msg.run!r}")
    _check_rules(msg, key_agent)
    return msg


# ---------------------------------------------------------------- encoding

def _plain(value):
    """msgspec's hook for what it cannot pack: numpy scalars and arrays, str subclasses."""
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    if isinstance(value, str):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not a message value")


_ENCODER = msgspec.msgpack.Encoder(enc_hook=_plain)


_VALID_RUNS: set[str] = set()  # the run ids encoded so far (a few), checked once each


def _check_run(run) -> None:
    try:
        validate_run_id(run)
    except ValueError as e:
        raise Rejected("bad-field:run", str(e)) from None
    if len(_VALID_RUNS) >= 64:
        _VALID_RUNS.clear()
    _VALID_RUNS.add(run)


def _unpackable(msg: Message) -> str:
    """The first field of ``msg`` msgpack cannot carry (some field could not be packed)."""
    for name in msg.__struct_fields__:
        try:
            _ENCODER.encode(getattr(msg, name))
        except (TypeError, ValueError, OverflowError, msgspec.EncodeError):
            return name
    return "?"


def encode(msg) -> bytes:
    """msgpack bytes of a message, unchecked beyond what msgpack can carry (the receiver parses
    them); raises Rejected (a ValueError) for a field msgpack cannot pack or a bad run id."""
    if type(msg) not in _HEADS:
        raise TypeError(f"not a message: {msg!r:.100}")
    run = msg.run
    if type(run) is not str or run not in _VALID_RUNS:
        _check_run(run)
    try:
        return _ENCODER.encode(msg)
    except (TypeError, ValueError, OverflowError, msgspec.EncodeError) as error:  # not packable
        raise Rejected(f"bad-field:{_unpackable(msg)}", str(error)) from None


def to_wire(msg) -> list:
    """The wire array of a message (what :func:`encode` packs), as plain values."""
    return _UNTYPED.decode(encode(msg))
