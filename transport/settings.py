"""How a process opens its Zenoh session: mode, endpoints, scouting, config file, in one place.

The embedded default (one machine, no router): the world is a peer listening on a loopback port;
agents are peers that listen on a free loopback port of their own and connect to the world, and
gossip scouting joins them into a full mesh, so a negotiation query goes straight from agent to
agent (``transport.topology``). Multicast scouting is always off unless a config file turns it
on. Across machines, pass a Zenoh config file and/or listen and connect endpoints (README,
"Several machines"; ``transport.zenoh_files``).
"""

import json
import logging
import os
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TypeVar

import zenoh

from nnql_swarm.transport.adapter import ProtocolAdapter, stop_on_signals
from nnql_swarm.transport.runtime import (
    ERROR_BACKTRACES_DEFAULT, ERROR_BACKTRACES_ENV, QUEUE_BATCHES, RUNTIME_DEFAULT, RUNTIME_ENV,
)

log = logging.getLogger("nnql.transport")

MODES = ("peer", "client", "router")

EXIT_TRANSPORT = 3
"""Exit code of a process that could not open its Zenoh session (the supervisor gives up)."""
EXIT_NO_WORLD = 4
"""Exit code of an agent whose world left and did not come back in time (``--world-wait``):
the supervisor does not restart it."""

_QUEUE_SIZES = "transport/link/tx/queue/size"


class TransportError(RuntimeError):
    """A Zenoh session could not be opened: no router to reach, bad credentials, bad config."""


@dataclass(frozen=True)
class TransportSettings:
    """How one process opens its Zenoh session."""

    mode: str = "peer"
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    config_file: str | None = None
    multicast: bool = False
    gossip: bool | None = None
    """Gossip scouting on or off; None leaves it to Zenoh (on) or to the config file."""
    connect_timeout_s: float = 0.0
    """How long a client keeps retrying its first connect (Zenoh's client default: not at all)."""
    rejoin_deaf_s: float = 0.0
    """An agent that is a client of the world as hub: how long its session may hear no other
    agent before the start before it opens another (``agent.agent_machine``); 0: not done."""

    def zenoh_config(self) -> zenoh.Config:
        """The ``zenoh.Config``: the file first (if any), then these settings on top, and
        :data:`QUEUE_BATCHES` always. Without a file, the shared-memory transport is off too: the
        swarm's messages are small bytes over TCP, and its 16 MiB segment would be resident in
        every process."""
        if self.mode not in MODES:
            raise ValueError(f"zenoh mode must be one of {', '.join(MODES)}, not {self.mode!r}")
        config = zenoh.Config.from_file(self.config_file) if self.config_file else zenoh.Config()
        config.insert_json5("mode", json.dumps(self.mode))
        if self.listen or not self.config_file:
            config.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        if self.connect or not self.config_file:
            config.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        if not self.config_file or self.multicast:
            config.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast))
        if not self.config_file:
            config.insert_json5("transport/shared_memory/enabled", "false")
        priorities = json.loads(config.get_json(_QUEUE_SIZES))  # Zenoh's own list of them
        config.insert_json5(_QUEUE_SIZES, json.dumps(dict.fromkeys(priorities, QUEUE_BATCHES)))
        if self.gossip is not None:
            config.insert_json5("scouting/gossip/enabled", json.dumps(self.gossip))
        if self.connect_timeout_s > 0:
            config.insert_json5("connect/timeout_ms", json.dumps(
                {"router": -1, "peer": -1, "client": round(self.connect_timeout_s * 1000)}))
        return config


def open_session(settings: TransportSettings) -> zenoh.Session:
    """Open the process's Zenoh session; a failure becomes one clear TransportError.

    Zenoh reads :data:`~nnql_swarm.transport.runtime.RUNTIME_ENV` when its first session opens,
    and Rust :data:`~nnql_swarm.transport.runtime.ERROR_BACKTRACES_ENV` at its first error, so
    they are set here (where the user has not)."""
    os.environ.setdefault(RUNTIME_ENV, RUNTIME_DEFAULT)
    os.environ.setdefault(ERROR_BACKTRACES_ENV, ERROR_BACKTRACES_DEFAULT)
    try:
        return zenoh.open(settings.zenoh_config())
    except zenoh.ZError as error:
        where = ", ".join(settings.connect or settings.listen) or settings.config_file or "defaults"
        reason = str(error).split(" at /")[0]  # drop the Rust source location
        raise TransportError(f"cannot open a Zenoh {settings.mode or 'session'} ({where}): {reason}") from None


@contextmanager
def closing(session: zenoh.Session) -> Iterator[zenoh.Session]:
    """The session, closed when the block ends. A close that times out (Zenoh closing hundreds of
    links at once on a loaded machine: 512 agents) is logged, not raised: the process's work is
    done, and its stats and exit code are still to come."""
    try:
        yield session
    finally:
        try:
            session.close()
        except zenoh.ZError as error:
            log.warning("closing the Zenoh session: %s", str(error).split(" at /")[0])


Node = TypeVar("Node", bound=ProtocolAdapter)


def run_in_session(settings: TransportSettings, make_node: Callable[[zenoh.Session], Node]
                   ) -> tuple[Node, object] | None:
    """Open the process's session, make its node in it and run the node until it stops (a
    signal stops it too), the session closed after: the node and what its run returned; None
    where the session could not open, which is logged (the process exits with
    :data:`EXIT_TRANSPORT`)."""
    try:
        session = open_session(settings)
    except TransportError as error:
        log.error("%s", error)
        return None
    with closing(session):
        node = make_node(session)
        stop_on_signals(node)
        return node, node.run()
