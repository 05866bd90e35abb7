"""What the two protocol machines (``agent.agent_machine``, ``world.world_machine``) share: a phase named by
an enum, moved only by the machine's one transition table, and the way every input runs.

A machine lists its transitions as ``{(phase, event): next phase}`` (h11's manner), its phases
and events as :class:`Named` enums: an event that its table does not allow in the current phase
is a bug, and raises :class:`PhaseError`.
Each input is a method decorated :func:`an_input` (nothing happens once the machine is in its
final phase) or :func:`any_phase_input` (it runs in every phase, and says itself what it does in
the final one); either way it returns the effects (``protocol.effects``) it caused, in order.
"""

import enum
import functools
import logging
from typing import ClassVar

from nnql_swarm.protocol.effects import Log


class Named(enum.Enum):
    """The base of a machine's phases and events. A member is the one object of its name, and
    hashes as that object: the transition table is looked up at every input, and
    ``enum.Enum`` hashes a member by its name, in Python."""

    __hash__ = object.__hash__


class PhaseError(RuntimeError):
    """An event the machine's transition table does not allow in its current phase."""


class Machine:
    """A phase and its transition table; ``_out``, the current input's effects, in order."""

    TRANSITIONS: ClassVar[dict[tuple[enum.Enum, enum.Enum], enum.Enum]]
    FINAL: ClassVar[enum.Enum]
    """The phase in which inputs do nothing (those of :func:`an_input`)."""

    phase: enum.Enum
    _out: list

    def _go(self, event: enum.Enum) -> None:
        """Move to the phase the table gives for ``event`` in the current phase."""
        try:
            self.phase = self.TRANSITIONS[self.phase, event]
        except KeyError:
            raise PhaseError(f"{event.name} in phase {self.phase.name}") from None


def an_input(handler):
    """An input of a :class:`Machine` (its arguments positional): its effects, in order; none in
    its final phase."""
    @functools.wraps(handler)
    def run(self, *args):
        out = self._out = []
        if self.phase is not self.FINAL:
            handler(self, *args)
        return out
    return run


def any_phase_input(handler):
    """An input of a :class:`Machine` (its arguments positional) that runs in every phase: its
    effects, in order."""
    @functools.wraps(handler)
    def run(self, *args):
        out = self._out = []
        handler(self, *args)
        return out
    return run


class EffectLog:
    """A logger whose lines become :class:`~protocol.effects.Log` effects of the machine's current
    input (what ``protocol.messages.Inbox`` is given, so that its rejections are effects too)."""

    def __init__(self, owner: Machine) -> None:
        self.owner = owner

    def log(self, level: int, message: str, *args) -> None:
        self.owner._out.append(Log(level, message, args))

    def info(self, message: str, *args) -> None:
        self.log(logging.INFO, message, *args)

    def warning(self, message: str, *args) -> None:
        self.log(logging.WARNING, message, *args)

    def error(self, message: str, *args) -> None:
        self.log(logging.ERROR, message, *args)
