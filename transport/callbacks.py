"""How Zenoh calls the nodes' handlers: every handler is a :func:`callback`.

:data:`CALLBACKS_ENV` is the one switch: ``kept`` (the default), ``direct`` or ``indirect``;
read once, when this module is imported (so a process's children inherit it).

- ``indirect``: Zenoh's default. Each handler runs on a Python thread that zenoh-python starts
  for it, fed through a channel: a thread hand-over on every message.
- ``direct``: each handler runs right on Zenoh's network thread (``indirect=False``, which
  zenoh-python's stubs call unstable), without a hand-over.
- ``kept``: ``direct``, and that thread keeps its Python thread state from one callback to the
  next (:func:`keep_thread_state`).

Figures for the three: docs/design.md ("How Zenoh calls the handlers").
"""

import ctypes
import logging
import os
import threading
from typing import Callable

import zenoh

CALLBACKS_ENV = "NNQL_ZENOH_CALLBACKS"
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
    """Keep the calling thread's Python thread state from one Zenoh callback to the next: one
    ``PyGILState_Ensure``, never released, on purpose.

    Kept because no Python API does it: Zenoh calls Python from its own threads through
    ``PyGILState_Ensure`` and ``_Release``, and on a thread Python did not start each pair
    creates a thread state and destroys it again, and with it the thread's ``threading.local``
    data (the codec's packer). One ``PyGILState_Ensure`` left outstanding keeps it for the
    thread's life, as CPython's documentation advises for threads that call into Python again
    and again (python/cpython#146219); the GIL is still released after each callback. On a
    thread that Python started it only raises a counter. Zenoh's threads outlive Python's
    finalization only once every session is closed, when they no longer call into it.
    """
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
