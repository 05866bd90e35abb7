"""The world process: ``world.world_machine.WorldMachine`` over a Zenoh session.

The machine keeps the clock (when a tick opens and closes, what goes to whom); this adapter
feeds it the intents and liveliness changes Zenoh delivers, with the time, and carries out its
effects: publish each observation on ``world/obs/<id>`` and the control messages, hand each
closed tick to ``on_tick`` (the launcher records it to Rerun there), write each episode's row
to ``episodes.csv`` (and, where the agents share one table, its checkpoint first), log. A resumed
world starts from the shared table of its checkpoint (``world.world_checkpoint``), which whoever starts
it reads (``WorldOptions.table``).

Threads, in three sentences. Every input reaches the machine under the node's one lock, and its
effects are carried out right there, in order, before the lock is let go, except the episode
rows: they sync a file, so they go to the main thread through its queue, in order. Intents are
handled on the thread Zenoh calls back on (its receiving thread, ``transport.runtime``), so the
last intent of a tick closes it and sends the next observations at once, while liveliness
changes are only queued there, because Zenoh calls those callbacks holding a lock of its own.
The main thread handles that queue (rows, liveliness) and the machine's timers, sleeping on the
queue until the next timer is due, at most ``transport.adapter.POLL_S``.
"""

import logging
import queue
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import zenoh

from nnql_swarm.protocol import trace
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.effects import Finished, Log, SendControl, SendObservations, TickClosed, WriteRow
from nnql_swarm.transport.runfiles import (
    EPISODES_FILE, next_incarnation, stats_path, write_json_atomic,
)
from nnql_swarm.transport.adapter import ProtocolAdapter
from nnql_swarm.transport.callbacks import callback, enqueue
from nnql_swarm.transport.runtime import declare_lockstep_publisher
from nnql_swarm.transport.slotfile import SlotFile
from nnql_swarm.transport.settings import (
    EXIT_TRANSPORT, TransportSettings, run_in_session,
)
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.engine import SwarmWorld, TickReport
from nnql_swarm.world.metrics import EpisodeWriter
from nnql_swarm.world.world_machine import WorldMachine
from nnql_swarm.world.shared_table import SharedState

log = logging.getLogger("nnql.world")

_PUT = zenoh.SampleKind.PUT


class RunFailed(RuntimeError):
    """The run cannot go on: not every agent came alive in time, or every agent left for good
    (``world.world_machine``)."""


@dataclass(frozen=True)
class WorldOptions:
    """How the world process runs."""

    config: SwarmConfig
    transport: TransportSettings
    out_dir: Path
    startup_timeout_s: float | None = None  # None: world.world_machine.startup_timeout of the agents
    first_episode: int = 0
    first_tick: int = 0
    table: SharedState | None = None  # the shared state a resumed run starts from


class WorldNode(ProtocolAdapter):
    """The machine's adapter to one Zenoh session (see the module docstring)."""

    protocol: WorldMachine

    def __init__(self, options: WorldOptions, session: zenoh.Session,
                 on_tick: Callable[[SwarmWorld, TickReport], None] | None = None,
                 before_row: Callable[[], None] | None = None) -> None:
        self.options = options
        self.before_row = before_row
        self.config = options.config
        self.session = session
        self.trace = trace.TickTrace.from_env("world")
        self.created_at = time.time()  # wall clock, for the stats' start-up: the protocol's is monotonic
        self.table_file = world_checkpoint.table_path(options.out_dir)
        self._table_slots = SlotFile(self.table_file)  # written by this process only
        self.protocol = WorldMachine(self.config, time.monotonic(), options.first_episode,
                                      options.first_tick, options.startup_timeout_s, self.trace,
                                      options.table, next_incarnation(options.out_dir))
        self.events: queue.SimpleQueue = queue.SimpleQueue()
        self.lock = threading.RLock()
        self.stopping = False
        self.failure: BaseException | None = None
        self.handler_cpu = {}
        self.write_failed = False  # an episode's checkpoint or row could not be written
        self.on_tick = on_tick
        self.publishers: list[zenoh.Publisher] = []
        self.control: zenoh.Publisher | None = None
        self.writer: EpisodeWriter | None = None
        self._do = {SendObservations: self._send_observations, SendControl: self._send_control,
                    TickClosed: self._tick_closed, Log: self._log,
                    WriteRow: self._to_main_thread, Finished: self._to_main_thread}

    @property
    def world(self) -> SwarmWorld:
        return self.protocol.world

    def stop(self) -> None:
        self.stopping = True
        self.events.put((None, None))

    def _on_intent(self, sample: zenoh.Sample) -> None:
        self.feed(self.protocol.on_intent, str(sample.key_expr), sample.payload)

    # Effects, in order.

    def _send_observations(self, effect: SendObservations) -> None:
        publishers, mark = self.publishers, self.trace.mark
        for obs, payload in effect.observations:
            mark(trace.OBS_SENT, obs.tick)
            publishers[obs.agent].put(payload)

    def _send_control(self, effect: SendControl) -> None:
        assert self.control is not None, "control is sent only while the node runs"
        self.control.put(effect.payload)

    def _tick_closed(self, effect: TickClosed) -> None:
        if self.on_tick is not None:
            report = effect.report
            assert isinstance(report, TickReport), report
            self.on_tick(self.protocol.world, report)

    def _log(self, effect: Log) -> None:
        log.log(effect.level, effect.message, *effect.args)

    def _to_main_thread(self, effect) -> None:
        self.events.put((type(effect), effect))

    # The main thread.

    def run(self) -> bool:
        """Run every episode; True if the run completed, False if it was stopped."""
        run_id, s, protocol = self.config.run_id, self.session, self.protocol
        finished = None
        with (
            s.declare_subscriber(keys.intent_key_all(run_id), callback(self._on_intent)),
            s.liveliness().declare_subscriber(keys.alive_key_all(run_id, keys.ROLE_AGENT),
                                              enqueue(self.events, "alive"), history=True),
            declare_lockstep_publisher(s, keys.control_key(run_id)) as control,
            s.liveliness().declare_token(keys.alive_key(run_id, keys.ROLE_WORLD, 0)),
        ):
            self.control = control
            self.publishers = [declare_lockstep_publisher(s, keys.obs_key(run_id, i))
                               for i in range(self.config.n_agents)]
            try:
                while finished is None and not self.stopping:
                    kind, item = self.next_event()
                    if kind is WriteRow:
                        self._write(item)
                    elif kind is Finished:
                        finished = item
                    elif kind == "alive":
                        self.feed(protocol.on_liveliness, str(item.key_expr), item.kind == _PUT)
                    self.fire_timer_if_due()
            finally:
                with self.lock:
                    self.stopping = True
                    if not protocol.done:
                        self.perform(protocol.stop(time.monotonic()))
                if not self.write_failed:
                    self._write_queued_rows()
                if self.writer is not None:
                    self.writer.close()
                for publisher in self.publishers:
                    publisher.undeclare()
        if self.failure is not None:
            raise self.failure
        if finished is not None and finished.error is not None:
            raise RunFailed(finished.error)
        return finished is not None and finished.completed

    def _write(self, row: WriteRow) -> None:
        """Append an episode's row (the file is opened at the first: a world that never
        started leaves no ``episodes.csv``), after the shared table's checkpoint, if any, and
        after the episode is on its way to the recording (``before_row``). Once one could not
        be written (a full disk), no later episode is: its checkpoint, rewritten in place, would
        succeed where its row fails, and leave the checkpoint ahead of the rows a resume
        continues from."""
        try:
            self._write_row(row)
        except BaseException:
            self.write_failed = True
            raise

    def _write_row(self, row: WriteRow) -> None:
        if self.before_row is not None:
            with self.lock:  # the recording's ticks are logged under it
                self.before_row()
        if row.table is not None:
            assert isinstance(row.table, SharedState), row.table
            world_checkpoint.save(self._table_slots, row.table, row.row["episode"], self.config)
        if self.writer is None:
            self.writer = EpisodeWriter(self.options.out_dir / EPISODES_FILE)
        self.writer.write(row.row, row.duration_s, row.ticks, row.slowest_s, row.rejected)

    def _write_queued_rows(self) -> None:
        """The rows of ticks that closed while the main thread was stopping."""
        while True:
            try:
                kind, item = self.events.get_nowait()
            except queue.Empty:
                return
            if kind is WriteRow:
                self._write(item)


def run_world(options: WorldOptions,
              on_tick: Callable[[SwarmWorld, TickReport], None] | None = None,
              before_row: Callable[[], None] | None = None) -> int:
    """Entry point of the world process; returns its exit code. ``before_row()`` is called
    before each episode's row is written (the recording makes the episode durable)."""
    try:
        ran = run_in_session(options.transport, lambda session: WorldNode(
            options, session, on_tick, before_row))
    except RunFailed as error:
        log.error("%s", error)
        return 1
    if ran is None:
        return EXIT_TRANSPORT
    node, completed = ran
    node.trace.save()
    stats = {**node.protocol.stats(), "handler_cpu": node.handler_cpu_stats()}
    if stats["startup_s"] is not None:
        stats["started_at"] = node.created_at + stats["startup_s"]  # seconds since the epoch
    write_json_atomic(stats_path(options.out_dir, "world"), stats)
    inbox = node.protocol.inbox
    if inbox.total_rejected:
        log.warning("world rejected %d messages: %s", inbox.total_rejected,
                    dict(inbox.rejections))
    if node.world.violations:
        log.error("the world's invariants were broken %d times", node.world.violations)
        return 1
    return 0 if completed else 130
