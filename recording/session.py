"""The launcher's side of a run's recording: the viewer it starts, the plan it hands each
process, the merge at the end.

``--rerun-spawn`` starts the native viewer, ``--rerun-connect URL`` uses a running one,
``--rerun-serve-web`` serves the web viewer from the launcher (``recording.viewers``); every
process then also streams to that viewer. By default, or besides, each process saves its part
and the launcher merges the parts into ``<out>/run.rrd`` (``recording.sinks``,
``recording.merge``).
"""

import signal
import sys
import time
from pathlib import Path

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.merge import merge_parts
from nnql_swarm.recording.one_origin import OneOrigin
from nnql_swarm.recording.sinks import RecordingPlan
from nnql_swarm.recording.viewers import RecordingError, reachable, serve_web, spawn_viewer
from nnql_swarm.transport.runfiles import PARTS_DIR


class RecordingSession:
    """The launcher's side of the recording: viewer start-up, the plan for each process, merge.
    ``server``: the stream whose gRPC server serves the web viewer, if the launcher serves it."""

    def __init__(self, plan: RecordingPlan | None, out: Path, server=None,
                 web_url: str | None = None, front: "OneOrigin | None" = None) -> None:
        self.plan = plan
        self.out = Path(out)
        self.server = server
        self.web_url = web_url
        self.front = front  # the web viewer's one origin, with the server

    @staticmethod
    def start(args, config: SwarmConfig, out: Path) -> "RecordingSession":
        """From the launcher's Rerun options. A viewer that cannot be reached or started costs a
        warning on stderr: the run goes on, recording to file (unless ``--no-record``)."""
        parts = None if args.no_record else Path(out) / PARTS_DIR
        url, server, web_url, front = None, None, None, None
        if args.rerun_connect:
            url = args.rerun_connect
            if not reachable(url):
                print(f"rerun: no viewer answers at {url}; not streaming to it", file=sys.stderr)
                url = None
        elif args.rerun_spawn:
            try:
                url = spawn_viewer(args.rerun_port)
            except RecordingError as error:
                print(f"rerun: {error}; not streaming to a viewer", file=sys.stderr)
        elif args.rerun_serve_web:
            try:
                server, url, web_url, front = serve_web(config.run_id, args.rerun_port,
                                                        args.rerun_web_port)
            except RecordingError as error:
                print(f"rerun: {error}; not serving the web viewer", file=sys.stderr)
        plan = RecordingPlan(config.run_id, parts, url, getattr(args, "map_agent", 0),
                             getattr(args, "reference", False))
        return RecordingSession(plan if plan.enabled else None, out, server, web_url, front)

    @staticmethod
    def files_only(record: bool, config: SwarmConfig, out: Path) -> "RecordingSession":
        """Parts saved under ``out`` and merged at the end (``record``), or nothing."""
        return RecordingSession(RecordingPlan.to_files(config, out) if record else None, out)

    def finish(self, wait_for_viewers: bool = True) -> Path | None:
        """Merge the parts into ``run.rrd``; keep serving the web viewer until Ctrl-C if asked."""
        merged = merge_parts(self.out) if self.plan and self.plan.parts_dir else None
        if self.server is not None:
            previous = {s: signal.signal(s, _stop_waiting) for s in (signal.SIGINT, signal.SIGTERM)}
            try:
                if wait_for_viewers:
                    print(f"rerun: still serving the run at {self.web_url} ; press Ctrl-C to stop",
                          file=sys.stderr)
                    while True:
                        time.sleep(3600)
            except _StopWaiting:
                pass
            finally:
                for s, handler in previous.items():
                    signal.signal(s, handler)
                self.server.disconnect()
                if self.front is not None:
                    self.front.close()
        return merged


class _StopWaiting(Exception):
    """Ctrl-C or SIGTERM while the launcher keeps the web viewer up after the run."""


def _stop_waiting(*_signal) -> None:
    raise _StopWaiting
