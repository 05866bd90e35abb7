"""Where each process of a run sends its part of the recording: Rerun's own sinks.

Every process of a run (the world, each agent, or the one in-process runner) logs into the same
recording, whose id is the run id. By default each process saves its own part,
``<out>/rerun-parts/<role>.<pid>.rrd`` (``rr.FileSink``), which the launcher merges into
``<out>/run.rrd`` when the run ends (``recording.merge``); with a viewer, every process also
streams to it (``rr.GrpcSink``).
"""

import os
import sys
import threading
from dataclasses import dataclass
from pathlib import Path

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import PARTS_DIR

APP_ID = "nnql-swarm"


@dataclass(frozen=True)
class RecordingPlan:
    """Where every process of a run sends its part of the recording (picklable, for spawn)."""

    run_id: str
    parts_dir: Path | None = None  # save a part here (None: no file)
    url: str | None = None  # also stream to this viewer
    map_agent: int | None = 0  # whose known map the recording shows (recording.known_map_view)
    reference: bool = False  # the paper's QL's curves are in it (recording.reference)

    @staticmethod
    def to_files(config: SwarmConfig, out: Path) -> "RecordingPlan":
        return RecordingPlan(config.run_id, parts_dir=Path(out) / PARTS_DIR)

    @property
    def enabled(self) -> bool:
        return self.parts_dir is not None or self.url is not None

    def open(self, role: str, default_blueprint=None):
        """This process's ``rr.RecordingStream`` into the run's recording; ``role`` names its
        part file."""
        import rerun as rr

        stream = rr.RecordingStream(APP_ID, recording_id=self.run_id)
        sinks: list[rr.FileSink | rr.GrpcSink] = []
        if self.parts_dir is not None:
            Path(self.parts_dir).mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(Path(self.parts_dir) / f"{role}.{os.getpid()}.rrd")))
        if self.url is not None:
            sinks.append(rr.GrpcSink(self.url))
        stream.set_sinks(*sinks)
        if default_blueprint is not None:
            # Made active, not only the default: a live viewer that has already built its own
            # layout from the agents' first data would keep that one.
            stream.send_blueprint(default_blueprint, make_active=True, make_default=True)
        return stream


def plan_of(record, config: SwarmConfig, out: Path) -> RecordingPlan | None:
    """A plan from what a launcher function was given: a plan, True (files), False/None (off)."""
    if isinstance(record, RecordingPlan):
        return record if record.enabled else None
    return RecordingPlan.to_files(config, out) if record else None


CLOSE_S = 3.0
"""How long closing a stream waits for its data to leave, and then for its sinks to close."""


def close_stream(stream, timeout_s: float = CLOSE_S, who: str = "the recording",
                 quiet: bool = False) -> None:
    """Flush and close ``stream`` (an ``rr.RecordingStream``), each step for at most
    ``timeout_s``: a viewer that went away, or a file the disk refused, costs a warning, not the
    run. Rerun's ``disconnect`` can wait for ever on a file sink whose writes failed (a full
    disk), so it waits in a thread of its own, which the process's exit ends. ``quiet``: the
    stream's failure was said already."""
    try:
        stream.flush(timeout_sec=timeout_s)
    except Exception as error:  # noqa: BLE001 - rerun raises RuntimeError for an unreachable viewer
        if not quiet:
            print(f"rerun: could not flush {who}: {error}", file=sys.stderr)
    closing = threading.Thread(target=stream.disconnect, name="rerun-disconnect", daemon=True)
    closing.start()
    closing.join(timeout_s)
    if closing.is_alive():
        print(f"rerun: {who} did not close within {timeout_s:g} s; its file may lack its last "
              f"ticks", file=sys.stderr)
