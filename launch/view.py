#!/usr/bin/env python3
"""Open a saved recording in Rerun, with or without a display.

    python launch/view.py runs/<run-id>          # or the installed command: nnql-view runs/<run-id>
    python launch/view.py runs/<run-id>/run.rrd --web

Where there is a screen (``DISPLAY`` or ``WAYLAND_DISPLAY`` set, or not Linux) this opens the
native viewer. Where there is none, or with ``--web``, it runs Rerun's web viewer server
(``rerun --serve-web``: the recording sent into its gRPC server, the viewer served over HTTP),
prints the URL to open (from another machine, or through an SSH tunnel of both ports) and serves
until Ctrl-C. A run directory stands for its ``run.rrd``; a run cut short before its parts were
merged, for its ``rerun-parts/*.rrd``; an experiment's directory, for ``swarm_curves.rrd``.
"""

import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from nnql_swarm.recording.viewers import port_taken

if TYPE_CHECKING:
    from nnql_swarm.launch.cli import OneLineParser

RRD_MAGIC = b"RRF2"
"""The first bytes of a Rerun recording file."""


class ViewError(Exception):
    """A path that is not a recording, or a viewer that cannot start: one line, exit code 2."""


def recordings(path: Path) -> list[Path]:
    """The recording files ``path`` stands for; raises ViewError."""
    if path.is_dir():
        for name in ("run.rrd", "swarm_curves.rrd"):
            if (path / name).is_file():
                return [path / name]
        parts = sorted((path / "rerun-parts").glob("*.rrd"))
        if parts:
            return parts
        raise ViewError(f"{path} holds no recording (run.rrd, rerun-parts/*.rrd or "
                        f"swarm_curves.rrd); was it run with --no-record?")
    if not path.exists():
        raise ViewError(f"no such file or folder: {path}")
    try:
        with open(path, "rb") as f:
            head = f.read(len(RRD_MAGIC))
    except OSError as error:
        raise ViewError(f"cannot read {path}: {error.strerror or error}") from None
    if head != RRD_MAGIC:
        raise ViewError(f"{path} is not a Rerun recording (.rrd)")
    return [path]


def has_display() -> bool:
    """Whether a native window can open here: not Linux, or a display server is named."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def serve_web(files: list[Path], web_port: int, grpc_port: int, bind: str) -> int:
    """Serve ``files`` to the web viewer until Ctrl-C (or SIGTERM); returns the exit code.

    ``rerun --serve-web`` serves the page and the recording on this machine only
    (``recording.viewers.saved_run_server``); in front of it, on ``bind:web_port``, one origin
    for both (``recording.one_origin``), which a browser elsewhere can read."""
    from nnql_swarm.recording.one_origin import OneOrigin
    from nnql_swarm.recording.viewers import (
        RecordingError, last_line, public_host, saved_run_server, web_url,
    )
    from nnql_swarm.transport.ports import free_port

    for port in (web_port, grpc_port):
        if port_taken(bind, port):
            raise ViewError(f"port {port} is in use; choose others with --web-port and --grpc-port")
    page_port = free_port()
    previous = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with tempfile.TemporaryFile("w+") as log, \
                saved_run_server(files, grpc_port, page_port, log) as server:
            try:
                front = OneOrigin(bind, web_port, page_port, grpc_port)
            except OSError as error:
                raise ViewError(f"cannot listen on {bind}:{web_port}: "
                                f"{error.strerror or error}") from None
            try:
                local = "127.0.0.1" if bind in ("0.0.0.0", "::") else bind
                here = web_url(local, web_port)
                shown = ", ".join(str(f) for f in files)
                if bind in ("0.0.0.0", "::"):
                    there = web_url(public_host(), web_port)
                    print(f"serving {shown} to the web viewer at {there} (on this machine: "
                          f"{here}); Ctrl-C to stop", flush=True)
                else:
                    print(f"serving {shown} to the web viewer at {here}; Ctrl-C to stop",
                          flush=True)
                server.wait()
                raise ViewError(f"the web viewer server ended (exit code {server.returncode}): "
                                f"{last_line(log)}")
            finally:
                front.close()
    except RecordingError as error:
        raise ViewError(str(error)) from None
    except _Stopped:
        print("stopped", file=sys.stderr)
        return 0
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


class _Stopped(Exception):
    """Ctrl-C or SIGTERM while serving."""


def _stop(*_signal) -> None:
    raise _Stopped


def open_native(files: list[Path]) -> int:
    """The native viewer on ``files``, until its window closes; returns its exit code."""
    from nnql_swarm.recording.binary import rerun_binary

    try:
        code = subprocess.call([*rerun_binary(), *map(str, files)])
    except KeyboardInterrupt:
        return 0
    if code != 0:
        print(f"the native viewer ended with exit code {code}; --web serves the web viewer "
              f"instead", file=sys.stderr)
    return code


def build_parser() -> "OneLineParser":
    from nnql_swarm.launch.cli import OneLineParser

    p = OneLineParser(description="Open a saved run's Rerun recording: the native viewer where "
                                  "there is a display, else the web viewer, served with its URL "
                                  "until Ctrl-C.")
    p.add_argument("path", type=Path,
                   help="a run directory (its run.rrd), an experiment's directory or an .rrd file")
    p.add_argument("--web", action="store_true",
                   help="serve the web viewer even where there is a display")
    p.add_argument("--web-port", type=int, default=9090, help="HTTP port of the web viewer (9090)")
    p.add_argument("--grpc-port", type=int, default=9876,
                   help="port of the recording's gRPC server, on this machine only: the page "
                        "reads it through --web-port (9876)")
    p.add_argument("--bind", default="0.0.0.0",
                   help="address the web viewer listens on (0.0.0.0: every interface; "
                        "127.0.0.1: this machine only)")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    for name in ("web_port", "grpc_port"):
        if not 1 <= getattr(args, name) <= 65535:
            parser.error(f"--{name.replace('_', '-')} must be 1..65535")
    try:
        files = recordings(args.path)
        if args.web or not has_display():
            return serve_web(files, args.web_port, args.grpc_port, args.bind)
        return open_native(files)
    except ViewError as error:
        parser.error(str(error))  # one line, exit code 2


if __name__ == "__main__":
    sys.exit(main())
