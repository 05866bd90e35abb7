"""Live viewers for a run: the native viewer spawned, or the web viewer served, with Rerun's own
``rr.spawn``, ``rr.serve_grpc`` and ``rr.serve_web_viewer``; saved recordings sent to a viewer's
server; the viewer URLs and their checks."""

import argparse
import contextlib
import os
import re
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import IO, Iterator
from urllib.parse import quote, urlparse

from nnql_swarm.recording.binary import rerun_binary
from nnql_swarm.recording.sinks import APP_ID

DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090
VIEWER_START_S = 15.0
"""How long a viewer or server started for a run may take to accept connections."""
SPAWNED_S = 2.0
"""How long a spawned viewer may still take to accept connections once ``rr.spawn``, which
waits for it to listen, has returned."""


class RecordingError(RuntimeError):
    """The recording cannot go where it was asked to (no viewer at the URL, bad URL)."""


def grpc_url(port: int, host: str = "127.0.0.1") -> str:
    return f"rerun+http://{host}:{port}/proxy"


def web_url(host: str, web_port: int) -> str:
    """The web viewer's page at ``host``, reading the recording from the same origin
    (``recording.one_origin``)."""
    return f"http://{host}:{web_port}/?url={quote(grpc_url(web_port, host), safe='')}"


def check_viewer_url(url: str) -> str:
    """A viewer URL as ``--rerun-connect`` takes it; raises ArgumentTypeError otherwise."""
    parsed = urlparse(url)
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or not parsed.hostname \
            or parsed.path.rstrip("/") != "/proxy":
        raise argparse.ArgumentTypeError(
            f"expected a viewer URL such as {grpc_url(DEFAULT_GRPC_PORT)}, not {url!r}")
    return url


def reachable(url: str, timeout: float = 1.0) -> bool:
    """Whether something accepts TCP connections where the viewer URL points."""
    parsed = urlparse(url)
    default = 443 if parsed.scheme == "rerun+https" else DEFAULT_GRPC_PORT
    try:
        with socket.create_connection((parsed.hostname, parsed.port or default), timeout=timeout):
            return True
    except OSError:
        return False


def wait_until_reachable(url: str, timeout: float = VIEWER_START_S) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if reachable(url, timeout=0.5):
            return True
        time.sleep(0.2)
    return False


def port_taken(bind: str, port: int) -> bool:
    """Whether ``port`` cannot be listened on at ``bind``."""
    family = socket.AF_INET6 if ":" in bind else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((bind, port))
        except OSError:
            return True
    return False


def spawn_viewer(port: int) -> str:
    """Start the native viewer on ``port`` (``rr.spawn``, which uses the one already there);
    returns its URL. The viewer is detached: it stays open after the run and Ctrl-C.

    Checked here, as ``rr.spawn`` does not: a display to open on, and a viewer still listening
    once started (one that cannot open its window listens briefly, then exits)."""
    import rerun as rr

    url = grpc_url(port)
    if reachable(url):
        return url
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        raise RecordingError("no display for the native viewer (DISPLAY and WAYLAND_DISPLAY are "
                             "unset); --rerun-serve-web serves a web viewer instead")
    binary = rerun_binary()
    try:
        with _quiet_children():  # the viewer's log lines would break into the progress bars
            rr.spawn(port=port, connect=False, recording=rr.RecordingStream(APP_ID),
                     executable_path=binary[0] if len(binary) == 1 else None)
    except Exception as error:  # noqa: BLE001 - Rerun's own errors (no executable)
        raise RecordingError(f"cannot start the viewer: {error}") from None
    if wait_until_reachable(url, SPAWNED_S):  # rr.spawn has waited for it to listen
        time.sleep(0.5)
        if reachable(url, timeout=0.5):
            return url
    raise RecordingError(f"the viewer did not start on port {port}")


@contextlib.contextmanager
def _quiet_children():
    """Standard output and error on /dev/null while inside, for the children started there."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 1)
            os.dup2(null.fileno(), 2)
        yield
    finally:
        for fd, old in zip((1, 2), saved):
            os.dup2(old, fd)
            os.close(old)


def serve_web(run_id: str, grpc_port: int, web_port: int):
    """Serve the run to the web viewer from this process: a gRPC server the run's processes
    stream into, which keeps what they sent for viewers that come later (``rr.serve_grpc``),
    the web viewer's page (``rr.serve_web_viewer``, on a port of its own), and in front of both,
    on ``web_port`` of every interface, one origin for the page and its data
    (``recording.one_origin``). Returns ``(stream, url, web_url, front)``; the gRPC server lives
    as long as ``stream``, the front until its ``close``."""
    import rerun as rr

    from nnql_swarm.recording.one_origin import OneOrigin
    from nnql_swarm.transport.ports import free_port

    for port in (grpc_port, web_port):
        if port_taken("0.0.0.0", port):  # rr.serve_grpc would only log it
            raise RecordingError(f"port {port} is in use")
    stream = rr.RecordingStream(APP_ID, recording_id=run_id)
    page_port = free_port()
    try:
        url = stream.serve_grpc(grpc_port=grpc_port)
        rr.serve_web_viewer(web_port=page_port, open_browser=False, connect_to=url)
        front = OneOrigin("0.0.0.0", web_port, page_port, grpc_port)
    except Exception as error:  # noqa: BLE001 - Rerun's own errors (a port in use)
        stream.disconnect()
        raise RecordingError(f"cannot serve the web viewer on ports {grpc_port}/{web_port}: "
                             f"{error}") from None
    address = web_url(public_host(), web_port)
    print(f"rerun: web viewer at {address}", file=sys.stderr)
    return stream, url, address, front


@contextlib.contextmanager
def saved_run_server(files: list[Path], grpc_port: int, page_port: int,
                     log: IO[str]) -> Iterator[subprocess.Popen]:
    """``rerun --serve-web`` on this machine only, its gRPC server on ``grpc_port`` and the web
    viewer's page on ``page_port``, serving ``files`` (none: an empty server that runs stream
    to) until the block ends; it writes to ``log``. Started with no file, and the files sent
    once it listens (:func:`push_recordings`: given on its command line, they keep a core busy).
    Raises RecordingError where it does not listen within :data:`VIEWER_START_S`, with the last
    line it wrote, or a file holds no recording."""
    server = subprocess.Popen(
        [*rerun_binary(), "--serve-web", "--bind", "127.0.0.1", "--port", str(grpc_port),
         "--web-viewer-port", str(page_port)],
        stdout=log, stderr=log, start_new_session=True)
    try:
        if not _listening(server, (grpc_port, page_port)):
            raise RecordingError(f"rerun --serve-web did not start: {last_line(log)}")
        push_recordings(files, grpc_port)
        yield server
    finally:
        stop_process(server)


def _listening(server: subprocess.Popen, ports) -> bool:
    """Whether ``server`` listens on every one of ``ports`` of 127.0.0.1 within
    :data:`VIEWER_START_S` (False: it exited first, or did not)."""
    deadline = time.monotonic() + VIEWER_START_S
    waiting = list(ports)
    while waiting and time.monotonic() < deadline and server.poll() is None:
        if reachable(grpc_url(waiting[0]), timeout=0.5):
            waiting.pop(0)
        else:
            time.sleep(0.1)
    return not waiting and server.poll() is None


def last_line(log: IO[str]) -> str:
    """The last line a rerun process wrote to ``log``, without its terminal colours."""
    log.flush()
    log.seek(0)
    lines = re.sub(r"\x1b\[[0-9;]*m", "", log.read()).strip().splitlines()
    return lines[-1] if lines else "no output"


def push_recordings(files: list[Path], port: int) -> None:
    """Send saved recordings to the gRPC server on ``port`` of this machine (a ``rerun
    --serve-web`` started without them), each as the file holds it (its own application and
    recording ids, its blueprint) and as far as it can be read; returns once all is sent. Given
    the files on its command line instead, Rerun 0.41's server keeps a core busy for as long as
    it runs, once it has loaded them; fed this way it idles. Raises RecordingError for a file
    that holds no recording."""
    import rerun as rr

    for path in files:
        application, recording = _recording_ids(path)
        # A stream of the file's own ids adds no recording of its own to the server.
        stream = rr.RecordingStream(application, recording_id=recording, send_properties=False)
        stream.connect_grpc(grpc_url(port))
        _send_file(stream, path)


def _recording_ids(path: Path) -> tuple[str, str]:
    """The application and recording ids of the first recording in the file at ``path``. A file
    cut off mid-message (its process killed) is read as far as it goes, as Rerun's importer
    reads it: copied through it into a scratch file first."""
    import tempfile
    import warnings

    import rerun as rr

    def first(source: Path) -> tuple[str, str] | None:
        with warnings.catch_warnings():  # a file without its footer is scanned whole, and said so
            warnings.simplefilter("ignore")
            stores = rr.chunk.RrdReader(source).recordings()  # empty recordings left out
        return (stores[0].application_id, stores[0].recording_id) if stores else None

    try:
        found = first(path)
    except Exception:  # noqa: BLE001 - Rerun's own error for a file cut off mid-message
        with tempfile.TemporaryDirectory() as scratch:
            copy = Path(scratch) / "readable.rrd"
            stream = rr.RecordingStream(APP_ID, send_properties=False)
            stream.save(copy)
            _send_file(stream, path)
            found = first(copy)
    if found is None:
        raise RecordingError(f"{path} holds no recording")
    return found


def _send_file(stream, path: Path) -> None:
    """Send the file at ``path`` through ``stream`` (its sink set), as Rerun's importer reads it,
    then close the stream."""
    try:
        stream.log_file_from_path(path)
        stream.flush()  # waits for the file's importer too
    finally:
        stream.disconnect()


def public_host() -> str:
    """This machine's address as another machine would reach it (the outgoing interface's IP)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("8.8.8.8", 53))  # UDP: no packet is sent, this only picks a route
            address = probe.getsockname()[0]
        if not address.startswith("127."):
            return address
    except OSError:
        pass
    return socket.gethostname() or "localhost"


def stop_process(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=3)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
