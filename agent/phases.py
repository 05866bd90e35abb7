"""The agent machine's named phases, the events that move it and its one transition table
(``agent.agent_machine`` runs them), and the state of a negotiation in progress."""

import enum
from dataclasses import dataclass, field

from nnql_swarm.agent.negotiation import Plan
from nnql_swarm.protocol.phase_machine import Named
from nnql_swarm.protocol.messages import Observation


class Phase(Named):
    """Where an agent is in its run (see the module docstring)."""

    PEERS = "waiting to see every other agent"
    IDLE = "waiting for an observation"
    NEGOTIATING = "waiting for the answers of the neighbours asked"
    ASKING_MISSING = "waiting for the awaited intents no answer brought, asked directly"
    STOPPED = "stopped"


class Event(Named):
    """What moves an agent from one phase to another."""

    READY = "every other agent seen, or the wait for them over"
    AWAITS = "an observation whose decision waits for intents"
    ANSWERS_IN = "every asked neighbour answered, refused, or time ran out"
    DECIDED = "the awaited tick decided"
    WORLD_LEFT = "the world left: a new one starts afresh"
    STOP = "the world's shutdown, or the process stopping"


WAITING = (Phase.NEGOTIATING, Phase.ASKING_MISSING)
TRANSITIONS: dict[tuple[enum.Enum, enum.Enum], enum.Enum] = {
    (Phase.PEERS, Event.READY): Phase.IDLE,
    (Phase.PEERS, Event.WORLD_LEFT): Phase.PEERS,
    **{(phase, Event.AWAITS): Phase.NEGOTIATING for phase in (Phase.IDLE, *WAITING)},
    (Phase.NEGOTIATING, Event.ANSWERS_IN): Phase.ASKING_MISSING,
    **{(phase, Event.DECIDED): Phase.IDLE for phase in WAITING},
    **{(phase, Event.WORLD_LEFT): Phase.IDLE for phase in (Phase.IDLE, *WAITING)},
    **{(phase, Event.STOP): Phase.STOPPED for phase in Phase if phase is not Phase.STOPPED},
}
"""Every move an agent's machine makes: ``(phase, event) -> next phase``. A new observation
while waiting for intents (the world moved on, or the clock was followed again after a gap)
starts a new negotiation."""


@dataclass
class Pending:
    """An observation whose decision waits for intents, with its plan (``agent.negotiation.Plan``:
    whose intents it awaits, whom it asked...): which of them the brain decides with
    (``needed``), until when, the intents it knows without asking (``staying``: parked
    neighbours), and, once the answers are in, the ones it then asked for directly because no
    answer brought them (``missing``); neighbours that cannot answer (gone, or refusing the
    tick) are waited for no more (``refused``)."""

    obs: Observation
    plan: Plan
    needed: list[int]
    deadline: float
    staying: dict[int, int]
    missing: list[int] = field(default_factory=list)
    refused: set[int] = field(default_factory=set)  # asked, and no answer is coming


@dataclass(slots=True)
class OpenAsk:
    """One of this agent's asks, until it ends: whom it asked, for which tick, and for a
    standing query its generation (only the newest one's end closes the stream)."""

    agent: int
    tick: int
    generation: int | None = None
