"""Zenoh's runtime for every process of a run: one network thread, and what its sends need.

Every process runs Zenoh with one thread that waits on every socket, receives and sends
(:data:`RUNTIME_DEFAULT`, unless ``ZENOH_RUNTIME`` is set). What a handler sends on that thread
leaves once the handler returns, in one batch a link; so each link's queue holds
:data:`QUEUE_BATCHES` batches, and the lockstep's publishers batch
(:func:`declare_lockstep_publisher`). Figures: docs/design.md, "One network thread".
"""

import zenoh

from nnql_swarm.protocol.keys import MAX_AGENTS

RUNTIME_ENV = "ZENOH_RUNTIME"
RUNTIME_DEFAULT = (f"(rx: (worker_threads: 1, max_blocking_threads: {MAX_AGENTS}),"
                   " acc: (handover: rx), app: (handover: rx), net: (handover: rx),"
                   " tx: (handover: rx))")
"""Zenoh's runtime threads, unless ``ZENOH_RUNTIME`` says otherwise: one network thread, which
receives, and also runs the acceptor's, the application's, the network runtime's and the sending
runtime's tasks (``handover``). Our handlers run on that thread (``indirect=False``).

- One receiving thread: with two, each message wakes the idle one too (tokio's work stealing),
  and the handlers hop between threads.
- The acceptor, the application and the network runtime: a socket is registered with the
  reactor of the runtime that opened it, the acceptor's for a link accepted, the application's
  for one connected; on its own thread, that runtime would wake first for every message and
  then wake the receiving thread. Handed over, one thread waits on every socket and handles
  what arrives.
- The sending runtime (``tx``): on a thread of its own, every message a handler sends wakes it.
  Handed over, what a handler sends waits until the handler returns, and then leaves in one
  batch a link. It needs :func:`declare_lockstep_publisher`'s batched sends and
  :data:`QUEUE_BATCHES`: a handler's sends that filled a link's queue would wait for the thread
  they run on.
- The receiving runtime's pool of blocking threads holds up to one per possible agent
  (``protocol.keys.MAX_AGENTS``), not tokio's 50: a link's accepting takes one of them, and a
  full pool can leave a session's close waiting forever."""

ERROR_BACKTRACES_ENV, ERROR_BACKTRACES_DEFAULT = "RUST_LIB_BACKTRACE", "0"
"""Whether Zenoh's error values capture a stack backtrace (Rust's ``Backtrace::capture``), unless
``RUST_LIB_BACKTRACE`` is set: not. With ``RUST_BACKTRACE=1`` in the environment, every error
Zenoh makes and handles itself (each link of a session closed, a connect retried) walks its
thread's stack and reads the unwinding tables of Zenoh's library: 1 to 1.4 MiB more resident in
the agents that meet one, at 512 agents. Panics keep their backtraces (``RUST_BACKTRACE``)."""

QUEUE_BATCHES = 16
"""Batches in each priority's queue of a link (Zenoh's maximum; its default is 2). With the
sending tasks on the network thread (:data:`RUNTIME_DEFAULT`), the queue must hold everything one
handler sends onto one link: 16 batches of 64 KiB. A handler of the swarm sends a link a few
messages at most (the world an agent its observation; an agent its answers and intent, over the
hub's one link), each of at most ``protocol.messages.MAX_PAYLOAD_BYTES`` (64 KiB), and batched
(:func:`declare_lockstep_publisher`). Batches are allocated as they are used."""


def declare_lockstep_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher of the lockstep's messages (observations, intents, control): never dropped,
    and batched.

    - ``CongestionControl.BLOCK``: through a router one link carries every observation, and
      under load Zenoh's default (DROP) loses some, which stalls agents (README, "Several
      machines").
    - Not ``express``, and nor are the asks and answers: an express message is a batch of its
      own, and with the sending tasks on the network thread (:data:`RUNTIME_DEFAULT`) what a
      handler sends waits for it to return. More than :data:`QUEUE_BATCHES` express messages
      from one handler onto one link (an agent's first asks to its 63 peers, over the hub's one
      link) fill the queue and wait for themselves until the link closes. Batched, they share
      batches and leave together.
    """
    return session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
