"""Zenoh session settings for every process of a run: mode, endpoints, scouting, config file.

The embedded default (one machine, no router): the world is a peer listening on a loopback port;
agents are peers that listen on a free loopback port of their own and connect to the world, and
gossip scouting joins them into a full mesh, so a negotiation query goes straight from agent to
agent. Multicast scouting is always off unless a config file turns it on. Across machines, pass
a Zenoh config file and/or listen and connect endpoints (README, "Several machines").

Every process also runs Zenoh with one thread that waits on every socket, receives and sends
(:data:`RUNTIME_DEFAULT`, unless ``ZENOH_RUNTIME`` is set), so the lockstep's sends are batched
(:func:`declare_lockstep_publisher`), and every handler of the nodes is a
:func:`callback`: by default it runs on that thread, which keeps its Python thread state from
one call to the next; one switch, :data:`CALLBACKS_ENV`, turns either trick off.
"""

import ctypes
import itertools
import json
import logging
import os
import queue
import socket
import threading
import time
from dataclasses import dataclass, field
from typing import Callable, Protocol

import zenoh

from nnql_swarm.protocol.keys import MAX_AGENTS

MODES = ("peer", "client", "router")


EXIT_TRANSPORT = 3
"""Exit code of a process that could not open its Zenoh session (the supervisor gives up)."""


class TransportError(RuntimeError):
    """A Zenoh session could not be opened: no router to reach, bad credentials, bad config."""


RUNTIME_ENV = "ZENOH_RUNTIME"
RUNTIME_DEFAULT = (f"(rx: (worker_threads: 1, max_blocking_threads: {MAX_AGENTS}),"
                   " acc: (handover: rx), app: (handover: rx), net: (handover: rx),"
                   " tx: (handover: rx))")
"""Zenoh's runtime threads, unless ``ZENOH_RUNTIME`` says otherwise: one network thread, which
receives, and also runs the acceptor's, the application's, the network runtime's and the sending
runtime's tasks (``handover``). Our handlers run on that thread (``indirect=False``).

- One receiving thread: with two, each message woke the idle one too (tokio's work stealing),
  and the handlers hopped between threads; 24 % more ticks a second with one, on 2 cores and 9
  processes (docs/performance.md, "Where the time goes").
- The acceptor, the application and the network runtime: a socket is registered with the
  reactor of the runtime that opened it, the acceptor's for a link accepted, the application's
  for one connected. So every message that came in woke that runtime's thread first (an
  ``epoll_wait``), which then woke the receiving thread (an ``eventfd`` write): two thread
  wake-ups a message. Handed over, one thread waits on every socket and handles what arrives.
  ``bench/paired.py --pairs 3 --a-env ZENOH_RUNTIME='(rx: (worker_threads: 1))' --b-env
  ZENOH_RUNTIME='<those three>' -- --agents 8 --repeats 3 --episodes 10``: 1.10x the ticks a
  second (1.01, 1.20, 1.10).
- The sending runtime (``tx``): on a thread of its own, every message a handler sent woke it (a
  futex or ``eventfd`` write, then a switch of threads), and at 64 agents those wake-ups were
  most of our handlers' time (py-spy). Handed over, what a handler sends waits until the handler
  returns, and then leaves in one batch a link: ticks a second 1.16x at 64 agents, median of 8
  pairs (docs/performance.md, "One network thread"). It needs :func:`declare_lockstep_publisher`'s
  batched sends and :data:`QUEUE_BATCHES`: a handler's sends that filled a link's queue would
  wait for the thread they run on.
- The receiving runtime's pool of blocking threads holds up to one per possible agent
  (``protocol.keys.MAX_AGENTS``), not tokio's 50: a link's accepting takes one of them, which
  once came from the acceptor's own pool. With 50, the world of 128 agents filled it (51
  threads), and its session's close then waited forever, in 2 of 6 runs; with 1024, 6 of 6
  closed (32 to 53 threads at the peak)."""

QUEUE_BATCHES = 16
"""Batches in each priority's queue of a link (Zenoh's maximum; its default is 2). With the
sending tasks on the network thread (:data:`RUNTIME_DEFAULT`), the queue must hold everything one
handler sends onto one link: 16 batches of 64 KiB. A handler of the swarm sends a link a few
messages at most (the world an agent its observation; an agent its answers and intent, over the
hub's one link), each of at most ``protocol.messages.MAX_PAYLOAD_BYTES`` (64 KiB), and batched
(:func:`declare_lockstep_publisher`). Batches are allocated as they are used."""

_QUEUE_SIZES = "transport/link/tx/queue/size"

def declare_lockstep_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher of the lockstep's messages (observations, intents, control): never dropped,
    and batched.

    - ``CongestionControl.BLOCK``: through a router one link carries every observation, and
      under load Zenoh's default (DROP) lost some, which stalled agents (README, "Several
      machines").
    - Not ``express``, and nor are the asks and answers: an express message is a batch of its
      own, and with the sending tasks on the network thread (:data:`RUNTIME_DEFAULT`) what a
      handler sends waits for it to return. Express, more than :data:`QUEUE_BATCHES` messages
      from one handler onto one link (an agent's first asks to its 63 peers, over the hub's one
      link) filled the queue and waited for themselves, 5 s, until the link closed. Batched,
      they share batches and leave together.
    """
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)


def open_session(settings: "TransportSettings") -> zenoh.Session:
    """Open the process's Zenoh session; a failure becomes one clear TransportError.

    Zenoh reads :data:`RUNTIME_ENV` when its first session opens, so it is set here."""
    os.environ.setdefault(RUNTIME_ENV, RUNTIME_DEFAULT)
    try:
        return zenoh.open(settings.zenoh_config())
    except zenoh.ZError as error:
        where = ", ".join(settings.connect or settings.listen) or settings.config_file or "defaults"
        reason = str(error).split(" at /")[0]  # drop the Rust source location
        raise TransportError(f"cannot open a Zenoh {settings.mode or 'session'} ({where}): {reason}") from None


CALLBACKS_ENV = "NNQL_ZENOH_CALLBACKS"
"""The one switch for how Zenoh calls our handlers: ``kept`` (the default), ``direct`` or
``indirect``; read once, when this module is imported (so a process's children inherit it).

- ``indirect``: Zenoh's default. Each handler runs on a Python thread that zenoh-python starts
  for it, fed through a channel: a thread hand-over on every message.
- ``direct``: each handler runs right on Zenoh's receiving thread (``indirect=False``, which
  zenoh-python's stubs call unstable), without a hand-over.
- ``kept``: ``direct``, and that thread keeps its Python thread state from one callback to the
  next. Zenoh calls Python from its own threads through ``PyGILState_Ensure`` and ``_Release``;
  on a thread Python did not start, each pair creates a thread state and destroys it again, and
  with it the thread's ``threading.local`` data (the codec's packer). One ``PyGILState_Ensure``
  left outstanding keeps it for the thread's life, as CPython's documentation advises for
  threads that call into Python again and again (python/cpython#146219); the GIL is still
  released after each callback. On a thread that Python started it only raises a counter.
  Zenoh's threads outlive Python's finalization only once every session is closed, when they no
  longer call into it.

Measured with paired runs of ``bench/swarm_ticks.py --agents 8 --repeats 5 --episodes 10``
(``bench/paired.py --pairs 3``, 2026-12-01): ``kept`` 1.18x the ticks a second of ``direct``,
1.08x those of ``indirect`` (README, "where the time goes").
"""
CALLBACK_MODES = ("kept", "direct", "indirect")
CALLBACK_MODE = os.environ.get(CALLBACKS_ENV) or CALLBACK_MODES[0]
if CALLBACK_MODE not in CALLBACK_MODES:
    logging.getLogger("nnql.transport").warning(
        "%s=%s is none of %s; using %s", CALLBACKS_ENV, CALLBACK_MODE, ", ".join(CALLBACK_MODES),
        CALLBACK_MODES[0])
    CALLBACK_MODE = CALLBACK_MODES[0]

_KEPT_STATES: set[int] = set()
"""The threads (by ident) whose Python thread state is kept (:func:`keep_thread_state`)."""


def keep_thread_state() -> None:
    """Keep the calling thread's Python thread state from one Zenoh callback to the next
    (:data:`CALLBACKS_ENV`, ``kept``): one ``PyGILState_Ensure``, never released, on purpose."""
    ident = threading.get_ident()
    if ident not in _KEPT_STATES:
        _KEPT_STATES.add(ident)
        ctypes.pythonapi.PyGILState_Ensure()


def callback(function: Callable, drop: Callable | None = None,
             mode: str | None = None) -> zenoh.handlers.Callback:
    """A Zenoh handler that calls ``function(item)`` as ``mode`` (default
    :data:`CALLBACK_MODE`) says, and ``drop()`` when it ends. Every handler of the nodes is one
    of these."""
    mode = mode or CALLBACK_MODE
    if mode == "indirect":
        return zenoh.handlers.Callback(function, drop)
    if mode == "direct":
        return zenoh.handlers.Callback(function, drop, indirect=False)
    kept = _KEPT_STATES
    ident = threading.get_ident

    def on_zenoh_thread(item) -> None:
        if ident() not in kept:
            keep_thread_state()
        function(item)

    return zenoh.handlers.Callback(on_zenoh_thread, drop, indirect=False)


def enqueue(events, kind: str) -> zenoh.handlers.Callback:
    """A Zenoh handler that puts ``(kind, item)`` on the queue ``events`` and does nothing else:
    how the nodes hand their main thread the events off the tick's path (liveliness, control).

    It is a :func:`callback` like the others (by default on Zenoh's network thread, rather than
    on a Python thread of its own): a put never blocks.
    """
    put = events.put
    return callback(lambda item: put((kind, item)))


POLL_S = 0.05
"""The longest a node's main thread sleeps on its queue: a timer set meanwhile on Zenoh's thread
(a tick's deadline, a negotiation's time-out) is noticed at most this late, and so is a request
to stop."""


class Machine(Protocol):
    """A protocol machine as its adapter drives it: when its timer is next due, and that input."""

    def timer(self) -> float | None: ...

    def on_timer(self, now: float) -> list: ...


class ProtocolAdapter:
    """What the agent and world nodes share as adapters of their protocol machines: an input is
    fed under the node's one lock and its effects are carried out there, in order, each by the
    handler ``_do`` names for its type. A bug in either stops the node (its ``run`` re-raises
    ``failure`` on the main thread) instead of vanishing into Zenoh's thread. The main thread
    takes the node's queue of ``events`` (:meth:`next_event`) and fires the protocol's timer
    (:meth:`fire_timer_if_due`).

    A node sets ``lock``, ``stopping``, ``failure``, ``protocol``, ``events`` and ``_do``, and
    says how it stops."""

    lock: threading.RLock
    stopping: bool
    failure: BaseException | None
    protocol: Machine
    events: queue.SimpleQueue
    _do: dict[type, Callable]

    def stop(self) -> None:
        raise NotImplementedError

    def feed(self, handler: Callable, *args) -> None:
        """``handler(*args, now)``, a protocol input, then its effects."""
        with self.lock:
            if self.stopping:
                return
            try:
                self.perform(handler(*args, time.monotonic()))
            except Exception as error:  # noqa: BLE001 - re-raised by run() on the main thread
                self.failure = error
                self.stop()

    def perform(self, effects: list) -> None:
        do = self._do
        for effect in effects:
            do[type(effect)](effect)

    def next_event(self) -> tuple:
        """The next ``(kind, item)`` of the main thread's queue; ``(None, None)`` if none came
        before the protocol's timer is due, or within :data:`POLL_S`."""
        with self.lock:
            due = self.protocol.timer()
        wait = POLL_S if due is None else min(max(due - time.monotonic(), 0.0), POLL_S)
        try:
            return self.events.get(timeout=wait)
        except queue.Empty:
            return None, None

    def fire_timer_if_due(self) -> None:
        """Feed the protocol its timer if that is due."""
        with self.lock:
            due = self.protocol.timer()
        if due is not None and time.monotonic() >= due:
            self.feed(self.protocol.on_timer)


LOWEST_CHOSEN_PORT = 10_000
"""The lowest port :func:`free_port` picks (below it: well-known and registered services)."""

_PORT_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
_PORT_TRIES = itertools.count()


def _ephemeral_low() -> int:
    """The lowest port the kernel hands out for port 0 and outgoing connections."""
    try:
        with open(_PORT_RANGE_FILE) as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768  # Linux's default; elsewhere a guess


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that nobody listens on right now, below the kernel's ephemeral range.

    A port from that range (a bind to port 0) could be handed, before its owner binds it, to
    another process of the same run that binds port 0 (a mesh agent's listener) or connects out:
    the world of a test once failed to listen that way. Below the range only an explicit bind
    can take it. Each process searches from a place derived from its id, so that processes
    choosing at once start apart, and each call goes on from where the last stopped, so that
    one process choosing several ports gets different ones; where the range leaves no room
    below it, the kernel chooses.
    """
    span = _ephemeral_low() - LOWEST_CHOSEN_PORT
    for _ in range(max(span, 0)):
        port = LOWEST_CHOSEN_PORT + (os.getpid() * 7919 + next(_PORT_TRIES)) % span
        with socket.socket() as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
            return port
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


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

    def to_dict(self) -> dict:
        return {"mode": self.mode, "listen": list(self.listen), "connect": list(self.connect),
                "config_file": self.config_file, "multicast": self.multicast,
                "gossip": self.gossip, "connect_timeout_s": self.connect_timeout_s}

    @staticmethod
    def from_dict(data: dict) -> "TransportSettings":
        return TransportSettings(
            mode=data["mode"], listen=tuple(data["listen"]), connect=tuple(data["connect"]),
            config_file=data.get("config_file"), multicast=bool(data.get("multicast", False)),
            gossip=data.get("gossip"),
            connect_timeout_s=float(data.get("connect_timeout_s", 0.0)),
        )

    def zenoh_config(self) -> zenoh.Config:
        """The ``zenoh.Config``: the file first (if any), then these settings on top, and
        :data:`QUEUE_BATCHES` always. Without a file, the shared-memory transport is off too: the
        swarm's messages are small bytes over TCP, and its 16 MiB segment was resident in every
        process (77 MiB an agent at 64 agents, 57 without)."""
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


TOPOLOGIES = ("mesh", "hub-peer", "hub-router", "router", "star-peers")

HUB_FROM_AGENTS = 32
"""From this many agents the launcher's embedded layout is ``hub-peer`` rather than ``mesh``
(``embedded_topology``): measured with ``bench/scale.py --topology`` at constant density, the
mesh ticks faster at 8 agents (355 against 285 ticks a second) and about as fast at 32 (46 and
47 against 45 and 43), but there each agent holds 61 MiB against 55 (a link per peer); at 64 the
hub gives 16 against 13 ticks a second, a start-up of 12.4 s against 16.5 and no missed intent in
the first episode against 51 (every peer's mesh of 63 links takes long to form)."""


HUB_CONNECT_S = 60.0
"""How long an agent that is a client of the hub keeps retrying its connect: 128 agents that
connect at once to a world still starting up on two cores were refused, and a Zenoh client by
default does not retry."""


def embedded_topology(n_agents: int) -> str:
    """The launcher's one-machine topology for a swarm of ``n_agents``."""
    return "hub-peer" if n_agents >= HUB_FROM_AGENTS else "mesh"


def wait_listening(host: str, port: int, timeout_s: float = 30.0) -> bool:
    """Until something accepts TCP connections on ``host:port`` (a hub's Zenoh listener);
    False if nothing did within ``timeout_s``. A client of the hub connects then at once, rather
    than at Zenoh's next retry (``connect_timeout_s``), a second or more later."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            socket.create_connection((host, port), timeout=1.0).close()
            return True
        except OSError:
            time.sleep(0.05)
    return False


@dataclass(frozen=True)
class EmbeddedLayout:
    """The one-machine layout: the hub (the world, or a router process) listens on ``port``;
    everyone else joins through it, as ``topology`` says."""

    port: int = field(default_factory=free_port)
    host: str = "127.0.0.1"
    topology: str = "mesh"

    def __post_init__(self) -> None:
        if self.topology not in TOPOLOGIES:
            raise ValueError(f"topology must be one of {', '.join(TOPOLOGIES)}")

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.host}:{self.port}"

    def router(self) -> TransportSettings | None:
        """The router process's settings, where the topology has one."""
        if self.topology != "router":
            return None
        return TransportSettings(mode="router", listen=(self.endpoint,), gossip=False)

    def world(self) -> TransportSettings:
        t = self.topology
        if t == "router":
            return TransportSettings(mode="client", connect=(self.endpoint,))
        mode = "router" if t in ("hub-router", "star-peers") else "peer"
        return TransportSettings(mode=mode, listen=(self.endpoint,),
                                 gossip=None if t == "mesh" else False)

    @property
    def agents_wait_for_hub(self) -> bool:
        """Whether agents must wait for the hub to listen (clients: not in the mesh)."""
        return self.topology not in ("mesh", "star-peers")

    def agent(self) -> TransportSettings:
        t = self.topology
        if t == "mesh":
            return TransportSettings(mode="peer", listen=(f"tcp/{self.host}:0",),
                                     connect=(self.endpoint,))
        if t == "star-peers":
            return TransportSettings(mode="peer", connect=(self.endpoint,), gossip=False)
        return TransportSettings(mode="client", connect=(self.endpoint,),
                                 connect_timeout_s=HUB_CONNECT_S)
