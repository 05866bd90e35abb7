"""The swarm command's options and flow, under the Python API: the parser, options to config,
the run directory, and the world and agent processes started under supervision (their entry
points: ``launch.processes``) or the in-process run.

:class:`nnql_swarm.api.Swarm` plays a run with these functions, and ``launch/swarm.py``
(``launch.swarm_cli``) is a Swarm made from the parsed options. On one machine Zenoh is
embedded in every process (peers on loopback, the world listening on a free port, no router, no
multicast). ``--role world`` / ``--role agents --agent-ids 0-3`` start parts of a run on several
machines; ``--in-process`` runs the very same logic in one process without Zenoh. The run
directory (``--out``, default ``runs/<run-id>``) receives ``config.json``, ``episodes.csv``,
``checkpoints/`` and the Rerun recording ``run.rrd``.
"""

import argparse
import logging
import math
from dataclasses import fields
import shlex
import sys
import time
from pathlib import Path
from typing import Any, Callable

from nnql_swarm.transport import zenoh_files
from nnql_swarm.launch.cli import (
    EXIT_INTERRUPTED, OneLineParser, invocation, prepare_simulator,
    episode_summary, progress as progress_bar,
)
from nnql_swarm.recording.merge import cut_at
from nnql_swarm.recording.session import RecordingSession
from nnql_swarm.recording.viewers import check_viewer_url
from nnql_swarm.sim.resume import (
    ResumeError, ResumePoint, read_config, resume_point, rewind, shared_table,
)
from nnql_swarm.sim.capacity import check_fits
from nnql_swarm.sim.supervisor import Supervisor, describe_exit
from nnql_swarm.sim.restarts import (
    STATS_NAME, record as record_restarts, warning as restarts_warning,
)
from nnql_swarm.protocol.config import (DEFAULT_PRESET, LEARNING_FIELDS, PRESETS,
                                        START_S_PER_AGENT, SwarmConfig)
from nnql_swarm.api.options import (
    LAUNCH_DEFAULTS as L, LAUNCHER_TOPOLOGIES, RUN_NAMES, Launch, config_of, config_values,
)
from nnql_swarm.transport.runfiles import (
    CHECKPOINT_DIR, CONFIG_FILE, EPISODES_FILE, EXIT_NO_SPACE, LOCK_FILE, PARTS_DIR,
    RECORDING_FILE, STATS_DIR, write_text_atomic,
)
from nnql_swarm.transport.runlock import RunLock, RunLocked
from nnql_swarm.transport.settings import EXIT_NO_WORLD, MODES, TransportSettings
from nnql_swarm.transport.topology import HUB_FROM_AGENTS, EmbeddedLayout, embedded_topology
from nnql_swarm.launch.processes import agent_main, process_context, world_main
from nnql_swarm.world.world_machine import STARTUP_TIMEOUT_S

log = logging.getLogger("nnql.launch")


class UsageError(Exception):
    """A bad option or value from the user: one line on stderr, exit code 2."""


def parse_ids(text: str) -> list[int]:
    """``"0-3,6"`` -> ``[0, 1, 2, 3, 6]``."""
    ids: list[int] = []
    try:
        for part in text.split(","):
            low, _, high = part.partition("-")
            ids.extend(range(int(low), int(high or low) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected ids such as 0-3,6, not {text!r}") from None
    return ids


def build_parser(parser: type[OneLineParser] = OneLineParser) -> OneLineParser:
    """The command's parser, of class ``parser`` (the Python API raises where it would exit)."""
    p = parser(description="A swarm run: a world process and one process per agent, "
                      "negotiating over Zenoh (--in-process: the same run in one process).")
    d = SwarmConfig()
    run = p.add_argument_group("the run")
    run.add_argument("--preset", default=None, metavar="{" + ",".join(PRESETS) + "}",
                     help=f"learning options by name (default: {DEFAULT_PRESET}, the swarm "
                          f"experiment's best; nnql or ql: the paper's reading); the options "
                          f"below override it")
    add_config_options(run, exclude=LEARNING_FIELDS)
    run.add_argument("--grid", default=argparse.SUPPRESS, metavar="WxH",  # read by the config's
                     help=f"grid size (default: {d.width}x{d.height})")
    run.add_argument("--map", default=None, metavar="FILE|SPEC",
                     help="the grid from a MovingAI .map file, or a generated one: "
                          "random:WxH:P[:SEED] (e.g. random:19x19:0.2), maze:WxH[:SEED], "
                          "warehouse[:WxH] (SEED defaults to --seed); starts and goals are "
                          "drawn per episode from its largest free region")
    run.add_argument("--scen", default=None, metavar="FILE",
                     help="with --map: a MovingAI .scen file whose first N lines (N = --agents) "
                          "are every episode's starts and goals")
    run.add_argument("--goals", default=None, metavar="FILE",
                     help="with --map and --tasks lifelong: a lifelong instance (.goals: each "
                          "agent's start and its goals in order, maps/pogema/*/lifelong); its "
                          "first N agents (N = --agents) start there every episode and are "
                          "given those goals in turn, then drawn ones")
    learning = p.add_argument_group("learning (each defaults to the preset's)")
    add_config_options(learning, only=LEARNING_FIELDS)
    run.add_argument("--run-id", default=None, help="default: <preset>-<agents>a-s<seed>-<time>")
    run.add_argument("--out", type=Path, default=None, help="run directory (default runs/<run-id>)")
    run.add_argument("--resume", action="store_true",
                     help="continue the run in --out after its last complete episode "
                          "(its config.json is the config)")
    run.add_argument("--in-process", action="store_true",
                     help="run world and agents in this process, without Zenoh")
    run.add_argument("--no-progress", action="store_true", help="no progress bar")
    z = p.add_argument_group("Zenoh (several machines)")
    z.add_argument("--role", choices=("all", "world", "agents"), default=L.role,
                   help="start everything, only the world, or only agents")
    z.add_argument("--agent-ids", type=parse_ids, default=None,
                   help="with --role agents: which agents to start, e.g. 0-3")
    z.add_argument("--world-wait", type=float, default=L.world_wait, metavar="SECONDS",
                   help="how long the agents wait for a world that left to come back before "
                        f"they stop (exit code {EXIT_NO_WORLD}; default: {L.world_wait:.0f})")
    z.add_argument("--agent-wait", type=float, default=L.agent_wait, metavar="SECONDS",
                   help="how long the world waits for every agent to come alive at the start, "
                        "and for one to come back once all have left, before it ends the run "
                        f"with an error (default: {STARTUP_TIMEOUT_S:.0f}, or "
                        f"{START_S_PER_AGENT:g} an agent if more)")
    z.add_argument("--port", type=int, default=None,
                   help="one machine: the loopback port the world listens on (default: a free one)")
    z.add_argument("--topology", choices=("auto", *LAUNCHER_TOPOLOGIES), default=L.topology,
                   help="one machine: mesh (every process a peer of every other), hub-peer or "
                        "hub-router (the agents clients of the world), star-peers (peers of the "
                        f"world only); auto: mesh below {HUB_FROM_AGENTS} agents, hub-peer from "
                        "then on (default: auto)")
    z.add_argument("--mode", choices=MODES, default=None,
                   help="Zenoh session mode (default: the config file's, else peer)")
    z.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help="Zenoh listen endpoint, e.g. tcp/0.0.0.0:7447 (repeatable)")
    z.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="Zenoh connect endpoint, e.g. tcp/192.0.2.1:7447 (repeatable)")
    z.add_argument("--zenoh-config", default=None, metavar="FILE", help="a Zenoh JSON5 config file")
    z.add_argument("--zenoh-config-dir", default=None, metavar="DIR",
                   help="one Zenoh config per process: DIR/world.json5, DIR/agent-<id>.json5 "
                        "(launch/secure.py writes them)")
    v = p.add_argument_group("Rerun")
    v.add_argument("--no-record", action="store_true", help="do not write run.rrd")
    v.add_argument("--reference", action="store_true",
                   help="also play these settings with the paper's QL (in this process, "
                        "compiled) and plot its learning curves beside the run's")
    v.add_argument("--map-agent", type=int, default=L.map_agent, metavar="ID",
                   help="the agent whose known map and planned path the recording shows, where "
                        "the learners read a map (default: 0)")
    viewer = v.add_mutually_exclusive_group()
    viewer.add_argument("--rerun-spawn", action="store_true",
                        help="spawn the native Rerun viewer; every process streams to it")
    viewer.add_argument("--rerun-connect", type=check_viewer_url, default=None, metavar="URL",
                        help="stream to a running viewer, e.g. rerun+http://127.0.0.1:9876/proxy")
    viewer.add_argument("--rerun-serve-web", action="store_true",
                        help="serve the web viewer (for another machine); prints its URL and "
                             "keeps serving after the run until Ctrl-C")
    v.add_argument("--rerun-port", type=int, default=L.rerun_port,
                   help="gRPC port of the viewer that --rerun-spawn / --rerun-serve-web start")
    v.add_argument("--rerun-web-port", type=int, default=L.rerun_web_port,
                   help="HTTP port of the web viewer of --rerun-serve-web: the page and the "
                        "run's data, on one origin")
    return p


def add_config_options(group, only=None, exclude=()) -> None:
    """One option per :class:`SwarmConfig` field that has one (its metadata): its flag, type,
    help and default, all from the field. A field's choices are shown, and checked by the
    config (``SwarmConfig``), not by the parser: one check, one line, for the command and the
    API."""
    for f in fields(SwarmConfig):
        if "help" not in f.metadata or f.name in exclude or (only and f.name not in only):
            continue
        meta = dict(f.metadata)
        flags = meta.pop("flag") or "--" + f.name.replace("_", "-")
        text = meta.pop("help")
        choices = meta.pop("choices", None)
        if choices:
            meta["metavar"] = "{" + ",".join(choices) + "}"
        shown = "on" if f.default is True else "off" if f.default is False else f.default
        kwargs: dict[str, Any] = dict(dest=f.name, default=argparse.SUPPRESS,
                                      help=text if shown == "" or "default" in text
                                      else f"{text} (default: {shown})")
        if f.type is bool:
            kwargs["action"] = argparse.BooleanOptionalAction
        else:
            kwargs["type"] = f.type
        group.add_argument(*([flags] if isinstance(flags, str) else flags), **kwargs, **meta)


def cli_options(args: argparse.Namespace) -> dict:
    """The run's options among the command's parsed ones, by name (those not given absent, or
    None), as :func:`api.options.config_of` takes them."""
    names = [f.name for f in fields(SwarmConfig) if "help" in f.metadata] + list(RUN_NAMES)
    return {name: getattr(args, name) for name in names if hasattr(args, name)}


def given_values(args: argparse.Namespace) -> dict:
    """The config fields the command's options give explicitly (a preset's learning options
    among them), and the run id if given: what ``--resume`` compares with the run's."""
    try:
        given = config_values(cli_options(args))
    except ValueError as error:
        raise UsageError(str(error)) from None
    if args.run_id is not None:
        given["run_id"] = args.run_id
    return given


def resolve(args: argparse.Namespace) -> tuple[SwarmConfig, Launch, Path]:
    """The run's config, how it is played and its directory, from the command's parsed
    options; raises UsageError on bad values."""
    try:
        config = config_of(cli_options(args), args.run_id)
    except ValueError as error:
        raise UsageError(str(error)) from None
    launch = Launch.of(args)
    check_launch(launch, config, named=args.run_id is not None)
    return config, launch, launch.out or Path("runs") / config.run_id


def check_launch(launch: Launch, config: SwarmConfig, named: bool = True) -> None:
    """Refuse launch options that do not go together, or with the run's config (``named``: the
    run id was given, as the parts of a run on several hosts need); raises UsageError."""
    if not launch.in_process:
        check_distributable(config)
    if launch.topology != "auto" and (launch.role != "all" or launch.listen or launch.connect
                                      or launch.zenoh_config or launch.zenoh_config_dir):
        raise UsageError("--topology lays out one machine's embedded Zenoh; with --role, "
                         "--listen, --connect or a Zenoh config the layout is yours")
    if launch.zenoh_config and not Path(launch.zenoh_config).is_file():
        raise UsageError(f"no Zenoh config file at {launch.zenoh_config}")
    if launch.agent_ids is not None:
        if launch.role != "agents":
            raise UsageError("--agent-ids goes with --role agents")
        bad = [i for i in launch.agent_ids if not 0 <= i < config.n_agents]
        if bad:
            raise UsageError(f"agent ids {bad} out of range 0..{config.n_agents - 1}")
    if launch.port is not None and (launch.role != "all" or launch.listen or launch.connect):
        raise UsageError("--port sets the one-machine layout; with --role, --listen or --connect "
                         "give endpoints instead")
    if not 0 <= launch.map_agent < config.n_agents:
        raise UsageError(f"--map-agent {launch.map_agent} out of range 0..{config.n_agents - 1}")
    if not 0 < launch.world_wait < math.inf:
        raise UsageError(f"--world-wait must be positive and finite, not {launch.world_wait}")
    if launch.agent_wait is not None and not 0 < launch.agent_wait < math.inf:
        raise UsageError(f"--agent-wait must be positive and finite, not {launch.agent_wait}")
    if launch.port is not None and not 1 <= launch.port <= 65535:
        raise UsageError(f"--port must be 1..65535, not {launch.port}")
    check_zenoh_files(launch, config)
    if launch.role != "all" and not (launch.listen or launch.connect or launch.zenoh_config
                                     or launch.zenoh_config_dir):
        raise UsageError(f"--role {launch.role} needs --listen/--connect endpoints or "
                         f"--zenoh-config")
    if launch.role != "all" and not named:
        raise UsageError(f"--role {launch.role} needs --run-id, the same on every host")
    check_capacity(launch, config)


def check_capacity(args: Launch, config: SwarmConfig) -> None:
    """Refuse a run, or the part of one this host starts, that this machine cannot hold
    (``sim.capacity``); raises UsageError."""
    if args.in_process:
        processes, agents = 1, config.n_agents
    else:
        agents = 0 if args.role == "world" else len(agent_ids(args, config))
        processes = agents + (args.role != "agents")
    try:
        check_fits(processes, agents, config.max_steps, own_processes=not args.in_process)
    except ValueError as error:
        raise UsageError(str(error)) from None


def check_distributable(config: SwarmConfig) -> None:
    """Refuse options that only the in-process simulator plays; raises UsageError."""
    if config.algo == "oracle":
        raise UsageError("--algo oracle plans every agent's move centrally; run it with --in-process")
    if config.lookahead > 1:
        raise UsageError("--lookahead > 1 is played by the simulator only (add --in-process)")
    if config.frozen:
        raise UsageError("frozen play (learned tables played as they are) is the simulator's "
                         "only; play it in-process")


RUN_ENTRIES = (CONFIG_FILE, EPISODES_FILE, RECORDING_FILE, CHECKPOINT_DIR, STATS_DIR, PARTS_DIR,
               LOCK_FILE)
"""What a run directory holds (``transport.runfiles``); a folder with anything else is not a run."""


def prepare_out_dir(out: Path, config: SwarmConfig, role: str) -> RunLock | None:
    """Create the run directory and own it (its lock, :mod:`transport.runlock`; the caller releases
    it when the run ends; ``--role agents``, which shares the folder with the world's launcher
    on one host, takes none); never overwrite a run that is already there, nor write a run
    into a folder that holds anything but a run's files (those of a run that never finished an
    episode, or of the agents started first on this host, may be there). An unusable path (a
    file, or where no folder can be made) or a folder another run owns is a UsageError."""
    if out.exists() and not out.is_dir():
        raise UsageError(f"--out {out} is a file, not a folder")
    if role != "agents" and out.is_dir():
        if (out / LOCK_FILE).exists():
            own(out).release()  # a run going on there is named as such
        check_no_run(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise UsageError(f"cannot make the run directory --out {out}: "
                         f"{error.strerror or error}") from None
    if role == "agents":
        return None
    lock = own(out)
    try:
        check_no_run(out)  # a run that took and left the folder since the check above
        write_text_atomic(out / CONFIG_FILE, config.to_json() + "\n")
    except BaseException as error:
        lock.release()
        if isinstance(error, OSError):
            raise UsageError(f"cannot write the run's config in --out {out}: "
                             f"{error.strerror or error}") from None
        raise
    return lock


def check_no_run(out: Path) -> None:
    """Refuse a folder that holds a run, or files that are not a run's; raises UsageError."""
    if (out / EPISODES_FILE).exists():
        raise UsageError(f"{out} already holds a run ({EPISODES_FILE}); choose another --out, "
                         f"or continue it with --resume --out {out}")
    held = sorted(entry.name for entry in out.iterdir()
                  if entry.name not in RUN_ENTRIES and not entry.name.endswith(".tmp"))
    if held:
        raise UsageError(f"--out {out} is a folder that holds other files ({held[0]}"
                         f"{', ...' if len(held) > 1 else ''}), not a run; choose a new or "
                         f"empty one")


def own(out: Path) -> RunLock:
    """The lock of the run folder ``out`` (:mod:`transport.runlock`); raises UsageError where
    another run holds it."""
    try:
        return RunLock(out)
    except RunLocked as error:
        raise UsageError(str(error)) from None
    except OSError as error:
        raise UsageError(f"cannot lock the run directory --out {out}: "
                         f"{error.strerror or error}") from None


def resume(args: Launch, given: dict | None = None
           ) -> tuple[SwarmConfig, ResumePoint, Path, RunLock | None]:
    """The config, start point and directory of a run to continue (its rows past the cut
    dropped: ``sim.resume``), and the folder's lock (none for ``--role agents``), which
    the caller releases when the run ends; ``given``: config fields given with ``--resume``,
    which must be the run's (:func:`given_values`). Raises ResumeError or UsageError."""
    if args.out is None:
        raise UsageError("--resume needs --out DIR, the run directory to continue")
    if args.in_process:
        raise UsageError("--resume continues distributed runs only")
    if args.role == "agents" or not (Path(args.out) / CONFIG_FILE).is_file():
        return (*_resume(args, given or {}), None)  # (no run there: refused, no lock left)
    lock = own(args.out)
    try:
        return (*_resume(args, given or {}), lock)
    except BaseException:
        lock.release()
        raise


def _resume(args: Launch, given: dict) -> tuple[SwarmConfig, ResumePoint, Path]:
    """:func:`resume`, once the folder is owned."""
    assert args.out is not None
    agents = agent_ids(args, read_config(args.out)) if args.role != "world" else []
    config, start = resume_point(args.out, agents, world=args.role != "agents")
    check_same_options(args.out, config, given)
    check_zenoh_files(args, config)
    if args.role != "agents":
        shared_table(args.out, config, start)
        rewind(args.out, start)
        if not args.no_record:  # what is played again is recorded again, once
            cut_at(args.out, start.tick, config.run_id)
    if start.episode < config.episodes:
        again = f"; episodes {start.episode}..{start.episode + start.replayed - 1} are played " \
                f"again (not every process had saved them)" if start.replayed else ""
        print(f"resuming {config.run_id} at episode {start.episode} (tick {start.tick}){again}",
              file=sys.stderr)
    for lag in start.lagging:
        print(f"warning: {lag} (its process missed episode ends): every process goes on from "
              f"its newest checkpoint, and the run is not the one left alone", file=sys.stderr)
    return config, start, args.out


def check_same_options(out: Path, config: SwarmConfig, given: dict) -> None:
    """Refuse run options given with ``--resume`` that differ from the run's ``config.json``
    (a resumed run is the run it continues); raises UsageError."""
    differ = [name for name, value in given.items() if getattr(config, name) != value]
    if differ:
        shown = ", ".join(f"{name} {given[name]!r} (the run's: {getattr(config, name)!r})"
                          for name in differ)
        raise UsageError(f"--resume continues the run as {Path(out) / CONFIG_FILE} says; "
                         f"these options differ from it: {shown}")


def check_zenoh_files(args: Launch, config: SwarmConfig) -> None:
    """Every Zenoh config file this launcher will hand out exists and reads; else UsageError."""
    if args.zenoh_config and args.zenoh_config_dir:
        raise UsageError("give --zenoh-config or --zenoh-config-dir, not both")
    try:
        if args.zenoh_config_dir:
            agents = agent_ids(args, config) if args.role != "world" else []
            files = zenoh_files.config_files(Path(args.zenoh_config_dir), args.role != "agents",
                                             agents)
        else:
            files = {"all": args.zenoh_config} if args.zenoh_config else {}
        for path in files.values():
            zenoh_files.file_mode(path)
    except ValueError as error:
        raise UsageError(str(error)) from None


def embedded_layout(args: Launch, n_agents: int):
    """The one-machine layout's ``(world settings, agent i -> settings, hub to wait for)``."""
    topology = embedded_topology(n_agents) if args.topology == "auto" else args.topology
    layout = EmbeddedLayout(topology=topology) if args.port is None else \
        EmbeddedLayout(topology=topology, port=args.port)
    return (layout.world(), lambda _agent: layout.agent(),
            (layout.host, layout.port) if layout.agents_wait_for_hub else None)


def transports(args: Launch, config: SwarmConfig):
    """The world's Zenoh settings, a function giving agent i's, and the ``(host, port)`` agents
    wait for before they open their sessions (None: they need not): embedded, or from the
    options."""
    if args.role == "all" and not (args.listen or args.connect or args.zenoh_config
                                   or args.zenoh_config_dir):
        return embedded_layout(args, config.n_agents)

    def explicit(config_file) -> TransportSettings:
        return zenoh_files.settings(args.mode, args.listen, args.connect, config_file)

    if args.zenoh_config_dir:
        directory = Path(args.zenoh_config_dir)
        world = explicit(directory / zenoh_files.WORLD_FILE) if args.role != "agents" else None
        return world, lambda agent: explicit(directory / zenoh_files.agent_file_name(agent)), None
    shared = explicit(args.zenoh_config)
    return shared, lambda _agent: shared, None


def run_in_process(config: SwarmConfig, out: Path, record, progress: bool,
                   on_row: Callable[[dict], None] | None = None, reference: bool = False) -> int:
    """``record``: a RecordingSession, or True / False for run.rrd or nothing; ``on_row(row)``
    follows each episode's row (its deterministic columns); ``reference``: the paper's QL
    curves into the recording too (``recording.reference``)."""
    from nnql_swarm.sim.inprocess import run_in_process as run
    from nnql_swarm.sim.runs import swarm_world
    from nnql_swarm.recording.loggers import InProcessRecorder
    from nnql_swarm.recording.session import RecordingSession

    prepare_simulator(swarm_world(config), config)  # before any recording stream opens
    session = record if isinstance(record, RecordingSession) else \
        RecordingSession.files_only(record, config, out)
    viz = InProcessRecorder(session.plan, config, out)
    if reference and session.plan is not None:
        play_reference(config, session.plan)
    bar = progress_bar(config.episodes, "episode") if progress else None
    collisions = 0

    def row_done(row: dict) -> None:
        nonlocal collisions
        collisions += row["collisions"]
        if bar is not None:
            bar.set_postfix(**episode_summary(row, config.n_agents, config.lifelong),
                            collisions=collisions, refresh=False)
            bar.update(1)
        if on_row is not None:
            on_row(row)

    recording = viz.world is not None
    try:
        result = run(config, out, viz.on_tick if recording else None,
                     on_episode_end=viz.on_episode_end if recording else None, on_row=row_done)
    finally:
        if bar is not None:
            bar.close()
        viz.close()
        session.finish()
    return 1 if result.violations else 0


def run_processes(args: Launch, config: SwarmConfig, out: Path,
                  start: ResumePoint, on_poll: Callable[[], bool | None] | None = None) -> int:
    """Start the world and/or agents as supervised processes and wait for the run to end;
    ``on_poll``: as ``Supervisor.run`` takes it."""
    world_transport, agent_transport, hub = transports(args, config)
    recording = RecordingSession.start(args, config, out)
    record, progress = recording.plan or False, not args.no_progress
    if args.reference and recording.plan is not None and args.role != "agents":
        play_reference(config, recording.plan)
    supervisor = Supervisor(process_context())  # the world and agents run the kernel uncompiled
    resumes = args.resume and start.cut >= 0  # a run started afresh loads no checkpoint
    world = None
    if args.role in ("all", "world"):
        world = supervisor.add("nnql-world", world_main, restartable=False, make_args=lambda _: (
            config, world_transport, out, record, progress, start, args.agent_wait))
    if args.role in ("all", "agents"):
        for i in agent_ids(args, config):
            def agent_args(restarted: bool, i: int = i) -> tuple:
                return (i, config, agent_transport(i), out, restarted or resumes, recording.plan,
                        hub, None if restarted else start.checkpoint_episode, args.world_wait)

            supervisor.add(f"nnql-agent-{i}", agent_main, restartable=True, make_args=agent_args)
    code = supervisor.run(leader=world, on_poll=on_poll)
    restarted = record_restarts(out, supervisor.restarted(),
                                STATS_NAME if args.role != "agents" else f"{STATS_NAME}-agents")
    merged = recording.finish()
    plan = recording.plan
    if code == 0 and plan is not None and plan.parts_dir and merged is None and unmerged(out):
        code = 1  # merge_parts said why; the parts stay, for the next --resume to merge
    if code == EXIT_NO_SPACE:
        print(f"no space left for the run's files in {out}: the run stopped; once there is "
              f"space, continue it with {resume_command(args, out)}", file=sys.stderr)
    elif code == EXIT_INTERRUPTED:
        print(f"\ninterrupted: the swarm stopped; continue it with {resume_command(args, out)}",
              file=sys.stderr)
    elif world is not None and code != 0:
        print(f"the world ended with {describe_exit(code)}; continue the run with "
              f"{resume_command(args, out)}", file=sys.stderr)
    elif code == EXIT_NO_WORLD:
        print(f"the agents stopped: no world for {args.world_wait:g} s (--world-wait); once "
              f"it runs again, continue with {resume_command(args, out)}", file=sys.stderr)
    said = restarts_warning(restarted)
    if said is not None:
        print(said, file=sys.stderr)
    return code


def unmerged(out: Path) -> bool:
    """Whether recording parts wait in ``out`` to be merged into ``run.rrd``."""
    return any((Path(out) / PARTS_DIR).glob("*.rrd"))


def play_reference(config: SwarmConfig, plan) -> None:
    """The paper's QL on these settings, its curves into the run's recording (a part of its
    own: ``recording.reference``)."""
    from nnql_swarm.recording.reference import log_reference

    print("playing the paper's QL on these settings for the reference curves", file=sys.stderr,
          flush=True)
    log_reference(config, plan.open("reference"))


def resume_command(args: Launch, out: Path) -> str:
    """The command line that continues this run: the program as it was called, ``--resume --out``
    and the options that are not in ``config.json`` (where the processes run and connect)."""
    words = [*invocation(), "--resume", "--out", str(out)]
    if args.role != "all":
        words += ["--role", args.role]
    if args.agent_ids is not None:
        words += ["--agent-ids", ",".join(map(str, args.agent_ids))]
    if args.topology != "auto":
        words += ["--topology", args.topology]
    if args.world_wait != L.world_wait:
        words += ["--world-wait", f"{args.world_wait:g}"]
    if args.agent_wait is not None:
        words += ["--agent-wait", f"{args.agent_wait:g}"]
    for flag, value in (("--mode", args.mode), ("--zenoh-config", args.zenoh_config),
                        ("--zenoh-config-dir", args.zenoh_config_dir)):
        if value is not None:
            words += [flag, value]
    for flag, endpoints in (("--listen", args.listen), ("--connect", args.connect)):
        for endpoint in endpoints:
            words += [flag, endpoint]
    if args.no_record:
        words.append("--no-record")
    return shlex.join(words)


def agent_ids(args: Launch, config: SwarmConfig) -> list[int]:
    return list(args.agent_ids) if args.agent_ids is not None else list(range(config.n_agents))
