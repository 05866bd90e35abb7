"""What every process sets up around Zenoh (protocol/transport.py), on real sessions on loopback.

Zenoh's runtime threads and Python thread states are per process, and what one test sets up lasts
for the rest of its process, so each check runs in a fresh spawned process.
"""

import multiprocessing as mp
import os
import threading
import time

import zenoh

from protocol import transport
from protocol.transport import TransportSettings, free_port

MESSAGES = 20


def _counts_seen_by_a_subscriber(keep_state: bool) -> dict[int, list[int]]:
    """Publish MESSAGES samples to a subscriber whose callback counts them in a
    ``threading.local``, the way the codec keeps its packer: by thread, what it counted at each."""
    local = threading.local()
    seen: dict[int, list[int]] = {}
    received = threading.Event()

    def count(sample) -> None:
        local.count = getattr(local, "count", 0) + 1
        seen.setdefault(threading.get_ident(), []).append(local.count)
        if sum(map(len, seen.values())) == MESSAGES:
            received.set()

    handler = (transport.callback(count) if keep_state
               else zenoh.handlers.Callback(count, indirect=False))
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with transport.open_session(TransportSettings(listen=(endpoint,))) as publishing, \
            transport.open_session(TransportSettings(connect=(endpoint,))) as subscribing:
        with subscribing.declare_subscriber("transport-test/count", handler):
            with publishing.declare_publisher("transport-test/count") as publisher:
                time.sleep(0.5)  # let the subscription reach the publisher
                for _ in range(MESSAGES):
                    publisher.put(b"x")
                    time.sleep(0.01)
                received.wait(5)
    return seen


def _run(keep_state: bool, results) -> None:
    results.put(_counts_seen_by_a_subscriber(keep_state))


def _in_fresh_process(keep_state: bool) -> dict[int, list[int]]:
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    process = ctx.Process(target=_run, args=(keep_state, results))
    process.start()
    try:
        return results.get(timeout=60)
    finally:
        process.join(10)


def test_zenohs_thread_keeps_its_python_state_from_one_callback_to_the_next():
    seen = _in_fresh_process(keep_state=True)
    assert sum(map(len, seen.values())) == MESSAGES
    for counts in seen.values():  # one receiving thread by default (transport.RUNTIME_DEFAULT)
        assert counts == list(range(1, len(counts) + 1))


def test_without_it_each_callback_starts_from_a_new_python_state():
    """Why keep_thread_state exists: should Zenoh ever keep the state itself, this fails, and
    the workaround can go."""
    seen = _in_fresh_process(keep_state=False)
    assert sum(map(len, seen.values())) == MESSAGES
    assert all(set(counts) == {1} for counts in seen.values())


def test_the_runtime_default_leaves_a_users_setting_alone(monkeypatch):
    monkeypatch.setenv(transport.RUNTIME_ENV, "(rx: (worker_threads: 2))")
    try:
        transport.open_session(TransportSettings(mode="peer")).close()
    except transport.TransportError:
        pass
    assert os.environ[transport.RUNTIME_ENV] == "(rx: (worker_threads: 2))"
