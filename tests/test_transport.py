"""What every process sets up around Zenoh (transport/), on real sessions on loopback.

Zenoh's runtime threads and Python thread states are per process, and what one test sets up lasts
for the rest of its process, so each check runs in a fresh spawned process.
"""

import multiprocessing as mp
import os
import socket
import threading
import time
from pathlib import Path

import pytest

from nnql_swarm.transport import callbacks, runtime
from nnql_swarm.transport.ports import LOWEST_CHOSEN_PORT, _ephemeral_low, free_port
from nnql_swarm.transport.settings import TransportError, TransportSettings, open_session

MESSAGES = 20


def _counts_seen_by_a_subscriber(mode: str | None) -> dict[int, list[int]]:
    """Publish MESSAGES samples to a subscriber (its handler made by ``callbacks.callback`` in
    ``mode``, None: the switch's) whose callback counts them in a ``threading.local``, the way
    the codec keeps its packer: by thread, what it counted at each."""
    local = threading.local()
    seen: dict[int, list[int]] = {}
    received = threading.Event()

    def count(sample) -> None:
        local.count = getattr(local, "count", 0) + 1
        seen.setdefault(threading.get_ident(), []).append(local.count)
        if sum(map(len, seen.values())) == MESSAGES:
            received.set()

    handler = callbacks.callback(count, mode=mode)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_session(TransportSettings(listen=(endpoint,))) as publishing, \
            open_session(TransportSettings(connect=(endpoint,))) as subscribing:
        with subscribing.declare_subscriber("transport-test/count", handler):
            with publishing.declare_publisher("transport-test/count") as publisher:
                time.sleep(0.5)  # let the subscription reach the publisher
                for _ in range(MESSAGES):
                    publisher.put(b"x")
                    time.sleep(0.01)
                received.wait(5)
    return seen


def _thread_names() -> list[str]:
    """The names of this process's threads (Zenoh names its runtimes' ``<runtime>-<n>``)."""
    return sorted(path.read_text().strip() for path in Path("/proc/self/task").glob("*/comm"))


def _run(mode: str | None, results) -> None:
    seen = _counts_seen_by_a_subscriber(mode)
    results.put((callbacks.CALLBACK_MODE, seen, _thread_names()))


def _in_fresh_process(mode: str | None,
                      switch: str | None = None) -> tuple[str, dict, list[str]]:
    """``(the switch's mode, what the subscriber saw, the process's thread names after it)`` in
    a fresh process whose :data:`callbacks.CALLBACKS_ENV` is ``switch``."""
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    old = os.environ.pop(callbacks.CALLBACKS_ENV, None)
    if switch is not None:
        os.environ[callbacks.CALLBACKS_ENV] = switch
    try:
        process = ctx.Process(target=_run, args=(mode, results))
        process.start()
    finally:
        os.environ.pop(callbacks.CALLBACKS_ENV, None)
        if old is not None:
            os.environ[callbacks.CALLBACKS_ENV] = old
    try:
        return results.get(timeout=60)
    finally:
        process.join(10)


def test_zenohs_thread_keeps_its_python_state_from_one_callback_to_the_next():
    mode, seen, _ = _in_fresh_process(mode=None)
    assert mode == "kept", "the default"
    assert sum(map(len, seen.values())) == MESSAGES
    for counts in seen.values():  # one receiving thread by default (runtime.RUNTIME_DEFAULT)
        assert counts == list(range(1, len(counts) + 1))


def test_without_it_each_callback_starts_from_a_new_python_state():
    """Why the ``kept`` mode exists: should Zenoh ever keep the state itself, this fails, and
    the workaround can go."""
    _, seen, _ = _in_fresh_process(mode="direct")
    assert sum(map(len, seen.values())) == MESSAGES
    assert all(set(counts) == {1} for counts in seen.values())


def test_the_one_switch_turns_the_tricks_off():
    mode, seen, _ = _in_fresh_process(mode=None, switch="indirect")
    assert mode == "indirect"
    assert sum(map(len, seen.values())) == MESSAGES
    assert all(ident != threading.main_thread().ident for ident in seen)
    for counts in seen.values():  # zenoh-python's own Python thread keeps its state anyway
        assert counts == list(range(1, len(counts) + 1))
    mode, _, _ = _in_fresh_process(mode=None, switch="sideways")
    assert mode == "kept", "an unknown value falls back to the default"


def test_one_thread_waits_on_every_socket_receives_and_sends():
    """runtime.RUNTIME_DEFAULT: the acceptor's, the application's, the network and the sending
    runtimes are handed over to the one receiving thread, which both a listening session (its
    accepted link) and a connecting one used. (Tokio names the threads of a runtime's blocking
    pool as its workers, so two sessions opened in one process may show more than ``rx-0``.)"""
    _, _, threads = _in_fresh_process(mode=None)
    runtimes = {name.split("-")[0] for name in threads}
    assert "rx" in runtimes and not runtimes & {"acc", "app", "net", "tx"}, threads


BURST = 200


def _burst_from_a_handler(results) -> None:
    """One handler sends BURST messages onto one link, as lockstep publishers; how many arrive
    within 3 s, and how long they took."""
    got, done = [], threading.Event()

    def count(sample) -> None:
        got.append(sample)
        if len(got) == BURST:
            done.set()

    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_session(TransportSettings(listen=(endpoint,))) as sender, \
            open_session(TransportSettings(connect=(endpoint,))) as receiver:
        out = [runtime.declare_lockstep_publisher(sender, f"transport-test/burst/{i}")
               for i in range(BURST)]

        def burst(_sample) -> None:
            for publisher in out:
                publisher.put(b"x" * 1000)

        with receiver.declare_subscriber("transport-test/burst/*", callbacks.callback(count)), \
                sender.declare_subscriber("transport-test/go", callbacks.callback(burst)), \
                receiver.declare_publisher("transport-test/go") as go:
            time.sleep(0.5)  # let the subscriptions reach the other session
            start = time.monotonic()
            go.put(b"")
            done.wait(3)
            results.put((len(got), time.monotonic() - start))
        for publisher in out:
            publisher.undeclare()


def test_a_handlers_many_sends_onto_one_link_leave_at_once():
    """The sending tasks run on the network thread, so what a handler sends leaves after it
    returns: the queue of a link must hold it all (runtime.QUEUE_BATCHES), and the lockstep's
    messages share batches (not express). Otherwise the handler waits for itself, 5 s, and the
    link closes."""
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    process = ctx.Process(target=_burst_from_a_handler, args=(results,))
    process.start()
    try:
        arrived, seconds = results.get(timeout=60)
    finally:
        process.join(10)
    assert arrived == BURST and seconds < 1.0, (arrived, seconds)


def test_the_runtime_default_leaves_a_users_setting_alone(monkeypatch):
    monkeypatch.setenv(runtime.RUNTIME_ENV, "(rx: (worker_threads: 2))")
    try:
        open_session(TransportSettings(mode="peer")).close()
    except TransportError:
        pass
    assert os.environ[runtime.RUNTIME_ENV] == "(rx: (worker_threads: 2))"


def _zenoh_tables_read_after_closing_a_link(environment: dict, results) -> None:
    """Two sessions linked on loopback, closed: how much of Zenoh's library's read-only data (its
    unwinding tables among it) this fresh process then holds resident, in KiB."""
    os.environ.update(environment)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    with open_session(TransportSettings(listen=(endpoint,))), \
            open_session(TransportSettings(connect=(endpoint,))):
        time.sleep(0.5)  # the link is up
    resident, zenoh_data = 0, False
    with open("/proc/self/smaps") as smaps:
        for line in smaps:
            if "-" in line.split()[0]:  # a mapping's first line
                zenoh_data = "zenoh" in line and " r--p " in line
            elif zenoh_data and line.startswith("Rss:"):
                resident += int(line.split()[1])
    results.put(resident)


def _zenoh_tables_read(environment: dict) -> int:
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    saved = os.environ.pop(runtime.ERROR_BACKTRACES_ENV, None)  # the child's own setting only
    try:
        process = ctx.Process(target=_zenoh_tables_read_after_closing_a_link,
                              args=(environment, results))
        process.start()
        resident = results.get(timeout=60)
        process.join(10)
    finally:
        if saved is not None:
            os.environ[runtime.ERROR_BACKTRACES_ENV] = saved
    return resident


def test_zenohs_errors_capture_no_backtrace_unless_the_user_asks():
    """With ``RUST_BACKTRACE=1`` (as on many a developer's machine), each error Zenoh makes and
    handles itself, here each link of a session closed, walks the stack and reads Zenoh's
    unwinding tables, some 1 MiB of them resident after; a process that opens its sessions with
    ``open_session`` does not (``transport.runtime.ERROR_BACKTRACES_ENV``), unless the user's
    ``RUST_LIB_BACKTRACE`` asks for it."""
    quiet = _zenoh_tables_read({"RUST_BACKTRACE": "1"})
    asked = _zenoh_tables_read({"RUST_BACKTRACE": "1", runtime.ERROR_BACKTRACES_ENV: "1"})
    assert quiet + 512 <= asked, f"Zenoh's read-only data resident: {quiet} KiB, asked {asked}"


def _zenoh_shared_memory_mapped(results) -> None:
    """After two sessions exchanged samples: the Zenoh shared-memory segments this process maps."""
    _counts_seen_by_a_subscriber(None)
    with open("/proc/self/maps") as maps:
        results.put(sorted({line.split()[-1] for line in maps if line.rstrip().endswith(".zenoh")}))


def test_sessions_map_no_shared_memory():
    """Zenoh's shared-memory transport maps a 16 MiB segment into every process that meets
    another on the machine (resident in each agent); the swarm sends bytes over TCP and turns it
    off where it writes the config itself."""
    ctx = mp.get_context("spawn")
    results = ctx.Queue()
    process = ctx.Process(target=_zenoh_shared_memory_mapped, args=(results,))
    process.start()
    try:
        assert results.get(timeout=60) == []
    finally:
        process.join(10)


def test_a_client_of_the_hub_keeps_connecting_until_the_hub_listens():
    """The embedded hub's agents retry their connect (128 of them at once were refused)."""
    from nnql_swarm.transport.topology import EmbeddedLayout

    layout = EmbeddedLayout(topology="hub-peer")
    agent = layout.agent()
    assert agent.mode == "client" and agent.connect_timeout_s >= 30
    hub_up = threading.Event()

    def hub_later() -> None:
        time.sleep(1.5)
        with open_session(layout.world()):
            hub_up.set()
            time.sleep(5)

    late = threading.Thread(target=hub_later)
    late.start()
    try:
        with open_session(agent):
            assert hub_up.is_set()
    finally:
        late.join()
    impatient = TransportSettings(mode="client", connect=(f"tcp/127.0.0.1:{free_port()}",))
    try:
        open_session(impatient).close()
        raise AssertionError("a client without the retry connected to nobody")
    except TransportError:
        pass


def test_free_ports_lie_below_the_kernels_ephemeral_range_and_differ_call_by_call():
    """A port the kernel could hand to a bind to port 0 or an outgoing connection is never
    chosen (the world of a test once lost its port that way), and one process choosing several
    gets several, skipping one that is taken."""
    low = _ephemeral_low()
    ports = [free_port() for _ in range(5)]
    assert len(set(ports)) == 5
    assert all(LOWEST_CHOSEN_PORT <= p < low for p in ports)
    span = low - LOWEST_CHOSEN_PORT

    def after(port):  # the next port the search tries
        return LOWEST_CHOSEN_PORT + (port + 1 - LOWEST_CHOSEN_PORT) % span

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", after(ports[-1])))
        assert free_port() == after(after(ports[-1]))


def test_a_session_close_that_times_out_is_logged_not_raised(caplog):
    """``settings.closing``: a Zenoh close that times out (512 agents' links on a loaded
    machine) ends the block quietly, with a warning; an error of the block itself still comes
    out."""
    import pytest
    import zenoh

    from nnql_swarm.transport.settings import closing

    class Session:
        closed = 0

        def close(self) -> None:
            Session.closed += 1
            raise zenoh.ZError("close operation timed out! at /zenoh/src/close.rs:135.")

    with closing(Session()) as session:
        assert isinstance(session, Session)
    assert Session.closed == 1
    assert "close operation timed out!" in caplog.text and "close.rs" not in caplog.text
    with pytest.raises(ValueError, match="the block's own"):
        with closing(Session()):
            raise ValueError("the block's own")
    assert Session.closed == 2
