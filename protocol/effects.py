"""What the protocol machines ask their adapters to do: small typed records, one per effect.

``agent.agent_machine.AgentMachine`` and ``world.world_machine.WorldMachine`` are pure: every input
(a payload that arrived, a query, a liveliness change, a timer at time ``now``) returns the list
of effects it causes, in the order they must be carried out. The Zenoh nodes (``agent.agent_node``,
``world.world_node``) carry them out on a real network and disk; the simulator (``sim``) carries them
between protocol instances in virtual time. Records that send a message hold both the message
(for whoever wants to look at it without decoding: the simulator's checks) and its encoded
payload (what goes on the wire).

Queries and asks are named by numbers: an agent numbers its own asks (``Ask.ask``), its adapter
numbers the queries it receives (``on_query(query, ...)``), and effects refer to them by those.
"""

from collections.abc import Iterator
from typing import NamedTuple

from nnql_swarm.protocol.messages import Answer, Control, Intent, Observation


class Log(NamedTuple):
    """A line for the process's log: ``logging`` level, message, and its %-arguments."""

    level: int
    message: str
    args: tuple = ()


# The agent's effects.

class SendIntent(NamedTuple):
    """Publish this agent's intent on its intent key (the world listens)."""

    intent: Intent
    payload: bytes


class Ask(NamedTuple):
    """Query ``agent``'s intent key with these selector parameters; replies come back as
    ``on_answer(ask, ...)``, the query's end as ``on_ask_end(ask, ...)`` (at the latest after
    ``timeout_s``)."""

    ask: int
    agent: int
    parameters: str
    timeout_s: float


class Reply(NamedTuple):
    """Reply to a received query with this agent's answer (the query stays open)."""

    query: int
    payload: bytes
    answer: Answer


class ReplyError(NamedTuple):
    """Reply to a received query with an error (why it cannot be answered)."""

    query: int
    message: bytes


class EndQuery(NamedTuple):
    """Finish a received query: no more replies to it."""

    query: int


class Checkpoint(NamedTuple):
    """Save the brain's tables atomically, as the state after ``episode``, before anything
    that follows this effect is carried out."""

    episode: int


class EpisodeEnded(NamedTuple):
    """An episode's last intent is out: the moment for what only reads the brain (heat maps)."""

    episode: int


class Stopped(NamedTuple):
    """The agent is done: the world said so (``by_world``), or it was stopped; or (``rejoin``)
    its session heard no other agent before the run began: the node opens a new session and
    starts again."""

    by_world: bool
    rejoin: bool = False


# The world's effects.

class SendObservations(NamedTuple):
    """Publish every agent's observation of a tick on its observation key, in the order
    ``observations`` yields them as ``(Observation, payload)``: each is built only when the one
    before it is taken, so that the first to decide is the first to know. Taken whole before
    the next input, as every effect is carried out."""

    observations: Iterator[tuple[Observation, bytes]]


class SendControl(NamedTuple):
    """Publish a control message to every process of the run."""

    control: Control
    payload: bytes


class TickClosed(NamedTuple):
    """A tick was applied; the world is as it left it until the next input (``on_tick``)."""

    report: object  # world.engine.TickReport


class WriteRow(NamedTuple):
    """Append one episode's row to ``episodes.csv``, with its wall-clock columns; where the
    agents share one table, checkpoint it first (``table``: a ``world.shared_table.SharedState``,
    the tables as the agents checkpointed them at that episode's end and its end tick's
    records)."""

    row: dict
    duration_s: float
    ticks: int
    slowest_s: float
    rejected: int
    table: object = None


class Finished(NamedTuple):
    """The world is done: the run completed, or it stopped (``error`` says why, if it failed)."""

    completed: bool
    error: str | None = None
