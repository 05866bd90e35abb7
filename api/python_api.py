"""The Python API: :class:`Swarm` configures a run, :meth:`Swarm.run` plays it in this process or
as the world and agent processes over Zenoh, and :class:`Run` reads what it left.

The command (``launch/swarm.py``) is a Swarm made from its parsed options
(:meth:`Swarm.from_args`) and played (:meth:`Swarm.play`). Options given here by name make the
run's config directly (``api.options.config_of``, the command's path from its parsed options
too; no argv, no parser), its values checked once, by the config, so a bad option raises
ValueError with the very line the command prints; the run directory is prepared, played and
recorded by the same functions, so a run made here and one made by ``launch/swarm.py`` with the
same options are the same run, file for file.
"""

import argparse
import csv
import io
import os
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Callable, Literal

import numpy as np

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.api import command
from nnql_swarm.api.options import Launch, config_of, split
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.jit import MODE_VARIABLE
from nnql_swarm.transport.runfiles import CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE, RECORDING_FILE
from nnql_swarm.transport.runlock import RunLock
from nnql_swarm.sim import restarts
from nnql_swarm.sim.resume import ResumeError, ResumePoint
from nnql_swarm.sim.supervisor import describe_exit
from nnql_swarm.launch.cli import EXIT_INTERRUPTED
from nnql_swarm.world import world_checkpoint
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import COLUMNS

DETERMINISTIC_COLUMNS = EPISODE_FIELDS
"""The columns of :attr:`Run.episodes` that the options alone decide: equal, bit for bit, between
runs of the same options, in-process or distributed. The others are wall-clock measures."""

_FLOAT_COLUMNS = ("reward_sum", "isr", "throughput", "duration_s", "ticks_per_s", "max_tick_ms")
EPISODE_DTYPE = np.dtype([(name, np.float64 if name in _FLOAT_COLUMNS else np.int64)
                          for name in COLUMNS])
"""The dtype of :attr:`Run.episodes`: ``episodes.csv``'s columns, in its order."""

Progress = Callable[[dict], None]
"""``progress(row)``: called as each episode ends, with its deterministic columns
(:data:`DETERMINISTIC_COLUMNS`) by name."""


class RunError(RuntimeError):
    """A run that ended without completing: its exit code (``code``) and directory (``path``)."""

    def __init__(self, message: str, code: int, path: Path) -> None:
        super().__init__(message)
        self.code, self.path = code, Path(path)


class Swarm:
    """A swarm run's options, checked: ``Swarm(agents=8, episodes=100, preset="nnql")``, or
    ``Swarm(config)`` with a :class:`~nnql_swarm.protocol.config.SwarmConfig`.

    Options are the command's (``launch/swarm.py --help``) by name, its flag or its config
    field's: ``agents`` or ``n_agents``, ``radius`` or ``interaction_radius``, ``deadline`` or
    ``tick_deadline_s``; ``grid=(width, height)`` or ``"WxH"``; a True or False for an on/off
    option; None for its default. A bad one raises ValueError with the command's line.
    :attr:`config` is the resolved config, with its run id (by default
    ``<preset>-<agents>a-s<seed>-<time>``, fixed when the Swarm is made).
    """

    launch: Launch
    _lock: RunLock | None = None
    config: SwarmConfig
    out: Path

    def __init__(self, config: SwarmConfig | None = None, **options) -> None:
        if config is not None and options:
            raise ValueError("give a SwarmConfig or options, not both")
        config_options, launch_options = split(options)
        if config is None:
            config = config_of(config_options)
        self._set(config, Launch(in_process=True, **launch_options), None)

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> "Swarm":
        """The Swarm of the command's parsed options (``api.command.build_parser``), every one
        of them kept: where the run goes, how its processes connect, what it records. Raises
        ``api.command.UsageError`` (the command's one line) for a bad one."""
        swarm = cls.__new__(cls)
        swarm.config, swarm.launch, swarm.out = command.resolve(args)
        return swarm

    def _set(self, config: SwarmConfig, launch: Launch, out: Path | None) -> None:
        """Take ``config`` played as ``launch`` says, into ``out`` (default ``runs/<run-id>``);
        raises ValueError where they do not go together (``api.command.check_launch``)."""
        _usage(command.check_launch, launch, config)
        self.config, self.launch = config, launch
        self.out = out or launch.out or Path("runs") / config.run_id

    def __repr__(self) -> str:
        return f"Swarm({self.config.run_id!r}: {self.config.n_agents} agents, " \
               f"{self.config.episodes} episodes)"

    def prepare(self) -> None:
        """Make the run directory (:attr:`out`), own it (``transport.runlock``, until :meth:`play`
        ends) and write its config; raises ``api.command.UsageError`` for a directory that is
        not usable, holds a run or is another run's."""
        self._lock = command.prepare_out_dir(self.out, self.config, self.launch.role)

    def play(self, on_row: "Progress | None" = None) -> int:
        """Play the prepared run as its options say (in this process, or as the world and the
        agent processes of ``--role``); returns the command's exit code. ``on_row(row)`` follows
        each episode's row."""
        args, config, path = self.launch, self.config, self.out
        try:
            if args.in_process:
                return command.run_in_process(config, path,
                                              command.RecordingSession.start(args, config, path),
                                              not args.no_progress, on_row=on_row,
                                              reference=args.reference)
            return _play_processes(args, config, path, ResumePoint(0, 0), on_row)
        finally:
            if self._lock is not None:
                self._lock.release()

    def run(self, out: str | Path | None = None, *, distributed: bool = False,
            record: bool = True, progress: Progress | bool | None = None) -> "Run":
        """Play every episode; returns the finished :class:`Run`.

        ``out``: the run directory (default ``runs/<run-id>``), which must not hold a run yet.
        ``distributed``: the world and one process per agent over Zenoh on this machine, as
        ``launch/swarm.py`` starts them; else the compiled simulator in this process
        (``--in-process``, much faster; the first run compiles it, about half a minute). Either
        way the same episodes and Q-tables. ``record``: write ``run.rrd``. ``progress``: a
        callable :data:`Progress`, or True for the command's progress bar on stderr.

        Raises ValueError for a bad option or an ``out`` that holds a run, KeyboardInterrupt if
        the run was interrupted (its files stay, as the command leaves them; a distributed run
        continues with :func:`resume`), and :class:`RunError` if it failed.
        """
        if not (progress is None or isinstance(progress, bool) or callable(progress)):
            raise ValueError(f"progress must be a callable, True or False, not {progress!r}")
        swarm = Swarm.__new__(Swarm)
        swarm._set(self.config, replace(self.launch, in_process=not distributed,
                                        no_record=not record, no_progress=progress is not True),
                   None if out is None else Path(out))
        _usage(swarm.prepare)
        code = swarm.play(progress if callable(progress) else None)
        return _finished(code, swarm.out, distributed)


def run(out: str | Path | None = None, *, config: SwarmConfig | None = None,
        distributed: bool = False, record: bool = True, progress: Progress | bool | None = None,
        **options) -> "Run":
    """``Swarm(config, **options).run(out, ...)`` in one call."""
    return Swarm(config, **options).run(out, distributed=distributed, record=record,
                                        progress=progress)


def resume(out: str | Path, *, progress: Progress | bool | None = None) -> "Run":
    """Continue the distributed run in ``out`` that was cut short, however it stopped, as
    ``launch/swarm.py --resume --out OUT`` does (to the very rows and Q-tables of the run left
    alone: docs/operations.md); returns it finished. A complete run is returned as it is.
    Raises ValueError where the directory cannot be resumed (the line names the file)."""
    args = Launch(out=Path(out), resume=True, no_progress=progress is not True)
    config, start, path, lock = _usage(command.resume, args)
    try:
        if start.episode >= config.episodes:
            return Run.open(path)
        code = _play_processes(args, config, path, start,
                               progress if callable(progress) else None)
    finally:
        if lock is not None:
            lock.release()
    return _finished(code, path, distributed=True)


def open_run(path: str | Path) -> "Run":
    """The run in ``path`` (:meth:`Run.open`)."""
    return Run.open(path)


class Run:
    """A run directory and what it holds (README, "What a run leaves"), as arrays.

    ``Run.open(path)`` reads any run directory, finished, interrupted or still going, made by the
    API or by the command.
    """

    def __init__(self, path: str | Path, config: SwarmConfig) -> None:
        self.path = Path(path)
        self.config = config

    @classmethod
    def open(cls, path: str | Path) -> "Run":
        """The run in ``path``; raises FileNotFoundError if it holds no ``config.json``, and
        ValueError if that is not a run's config."""
        config_file = Path(path) / CONFIG_FILE
        if not config_file.is_file():
            raise FileNotFoundError(f"{config_file}: no run here")
        try:
            return cls(path, SwarmConfig.from_json(config_file.read_text()))
        except (ValueError, TypeError) as error:
            raise ValueError(f"{config_file}: not a valid run config ({error})") from None

    def __repr__(self) -> str:
        return (f"Run({str(self.path)!r}: {self.config.run_id}, {len(self.episodes)} of "
                f"{self.config.episodes} episodes)")

    @property
    def episodes(self) -> np.ndarray:
        """``episodes.csv`` as a numpy structured array, one element per finished episode, one
        field per column (:data:`EPISODE_DTYPE`: integers, and floats for ``reward_sum`` and the
        wall-clock columns). ``run.episodes["collisions"]`` is a column; ``pandas.DataFrame(
        run.episodes)`` a data frame. Read from the file at every access."""
        file = self.path / EPISODES_FILE
        rows = _complete_rows(file.read_text()) if file.exists() else []
        table = np.zeros(len(rows), dtype=EPISODE_DTYPE)
        for name in COLUMNS:
            kind = float if name in _FLOAT_COLUMNS else int
            table[name] = [kind(row[name]) for row in rows]
        return table

    @property
    def restarts(self) -> dict[str, list[str]]:
        """The agents the supervisor restarted in a distributed run, each with how each exit it
        was restarted after ended (``stats/supervisor.json``): empty for the run its seed
        gives, which a run with restarts is no longer."""
        return restarts.of_run(self.path)

    @property
    def complete(self) -> bool:
        """Whether every episode of the config has its row."""
        return len(self.episodes) >= self.config.episodes

    def q_tables(self, agent: int) -> tuple[np.ndarray, np.ndarray]:
        """Agent ``agent``'s ``(Q_DS, Q_CA)`` from its checkpoint (the run's end, or for a run
        still going or cut short its last episode's): ``Q_DS`` is ``(441, 5)``, by the goal's
        offset from the agent (state ``(dy + 10) * 21 + dx + 10``) and action (UP, DOWN, LEFT,
        RIGHT, STAY: ``nnql_swarm.protocol.actions``); ``Q_CA`` is ``(441 * blocks, 5)``, by a
        neighbour's offset, in blocks of 441 states where the learning options give a neighbour
        several (``known_state``, ``nnql-dir``). With ``shared`` every agent's are the one
        shared table. Raises ValueError for an agent out of range or a checkpoint that cannot be
        read (the message names the file)."""
        if not (isinstance(agent, (int, np.integer)) and 0 <= agent < self.config.n_agents):
            raise ValueError(f"agent {agent!r} out of range 0..{self.config.n_agents - 1}")
        path = agent_checkpoint.checkpoint_path(self.path / CHECKPOINT_DIR, int(agent))
        saved = read_fields(path, ("q_ds", "q_ca"))
        return np.array(saved["q_ds"]), np.array(saved["q_ca"])

    def shared_table(self) -> tuple[np.ndarray, np.ndarray]:
        """The one ``(Q_DS, Q_CA)`` the agents share (``shared``, as in the default preset),
        from the world's checkpoint: equal to every agent's :meth:`q_tables`. Raises ValueError
        where every agent learns into its own tables."""
        if not self.config.shared:
            raise ValueError("the agents of this run learn each into its own tables "
                             "(shared is off): read them with q_tables(agent)")
        path = world_checkpoint.table_path(self.path)
        saved = read_fields(path, ("q_ds", "q_ca"))
        return np.array(saved["q_ds"]), np.array(saved["q_ca"])

    @property
    def recording(self) -> Path | None:
        """``run.rrd``, the Rerun recording of the whole run (None if the run was made without
        one); open it with the ``rerun`` command, or :meth:`show` it in a notebook."""
        path = self.path / RECORDING_FILE
        return path if path.is_file() else None

    def show(self, width: int | Literal["auto"] = "auto", height: int | Literal["auto"] = 720):
        """The run's recording in Rerun's notebook viewer, on the layout the command's viewer
        opens on (``recording.blueprint``): returned as a ``rerun.notebook.Viewer``,
        which a notebook cell shows inline when it is the cell's value (or call its
        ``display()``). ``width``, ``height``: pixels, or ``"auto"`` (the cell's width; a 16:9
        height).

        Needs the ``notebook`` extra (``pip install 'nnql-swarm[notebook]'``, which brings
        ``rerun-notebook``). The viewer's code comes from ``app.rerun.io`` unless
        ``RERUN_NOTEBOOK_ASSET`` says otherwise, set before the first ``show``: ``serve-local``
        serves it from this machine (docs/api.md). Raises FileNotFoundError if the run has no
        recording.
        """
        import rerun as rr
        import rerun.notebook
        from rerun.chunk import RrdReader

        from nnql_swarm.recording.blueprint import recorded_blueprint
        from nnql_swarm.recording.sinks import APP_ID

        path = self.recording
        if path is None:
            raise FileNotFoundError(f"{self.path / RECORDING_FILE}: no recording (the run was "
                                    f"made with record=False, or is still going)")
        chunks = RrdReader(str(path)).store().stream().to_chunks()
        stream = rr.RecordingStream(APP_ID, recording_id=self.config.run_id)
        viewer = rerun.notebook.Viewer(width=width, height=height, recording=stream,
                                       blueprint=recorded_blueprint(self.config, chunks))
        stream.send_chunks(chunks)
        stream.flush()  # the viewer holds every chunk until its page is ready for them
        return viewer


def _usage(function, *args):
    """``function(*args)``, its usage errors (the command's one line and exit code 2) raised as
    ValueError with the same line."""
    try:
        return function(*args)
    except (command.UsageError, ResumeError) as error:
        raise ValueError(str(error)) from None


def _play_processes(args: Launch, config: SwarmConfig, path: Path,
                    start: ResumePoint, progress: Progress | None) -> int:
    """The world and agent processes of a run, as the command starts them, and their exit code;
    ``progress`` follows ``episodes.csv`` as the world writes it."""
    follower = _RowFollower(path / EPISODES_FILE, start.episode, progress) if progress else None
    with _kernel_mode_kept():
        code = command.run_processes(args, config, path, start,
                                     on_poll=follower.poll if follower else None)
    if follower is not None:
        follower.poll()
        if follower.error is not None:
            raise follower.error
    return code


def _finished(code: int, path: Path, distributed: bool) -> "Run":
    if code == EXIT_INTERRUPTED:
        raise KeyboardInterrupt(f"the swarm stopped; its files are in {path}")
    if code != 0:
        how = "broke an invariant of the world" if not distributed else describe_exit(code)
        again = f"; continue it with nnql_swarm.api.resume({str(path)!r})" if distributed else ""
        raise RunError(f"the run in {path} ended with {how}{again}", code, path)
    return Run.open(path)


@contextmanager
def _kernel_mode_kept():
    """Leave ``NNQL_KERNEL`` as it was: the command sets it for the processes it starts, and
    processes this one starts later must not inherit it."""
    before = os.environ.get(MODE_VARIABLE)
    try:
        yield
    finally:
        if before is None:
            os.environ.pop(MODE_VARIABLE, None)
        else:
            os.environ[MODE_VARIABLE] = before


class _RowFollower:
    """Hands each new complete row of ``episodes.csv`` to ``progress`` (polled by the
    supervisor); an exception of ``progress`` stops the run and is kept in ``error``."""

    def __init__(self, file: Path, delivered: int, progress: Progress) -> None:
        self.file, self.delivered, self.progress = file, delivered, progress
        self.size = -1
        self.error: BaseException | None = None

    def poll(self) -> bool:
        if self.error is not None:
            return True
        try:
            size = self.file.stat().st_size
            if size == self.size:
                return False
            text = self.file.read_text()
        except FileNotFoundError:
            return False
        self.size = size
        try:
            for row in _complete_rows(text)[self.delivered:]:
                self.delivered += 1
                self.progress({name: (float if name in _FLOAT_COLUMNS else int)(row[name])
                               for name in DETERMINISTIC_COLUMNS})
        except Exception as error:  # noqa: BLE001 (handed back to the caller once stopped)
            self.error = error
            return True
        return False


def _complete_rows(text: str) -> list[dict]:
    """The rows of an ``episodes.csv`` text whose line is whole (the last may be half written)."""
    return list(csv.DictReader(io.StringIO(text[:text.rfind("\n") + 1])))
