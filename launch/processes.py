"""What each process of a swarm runs: the world's and an agent's entry points, and how they start.

Apart from the command line (``launch.swarm_cli``) so that an agent imports only what it runs:
the processes are forked from a server that imported the nodes once (:func:`process_context`),
and an agent's resident memory is the measure (``bench/scale.py``). Rerun is imported inside,
by a process that records.
"""

import logging
import multiprocessing as mp
import os
import sys
import time
from multiprocessing import forkserver, resource_tracker, spawn
from multiprocessing.context import ForkServerContext, SpawnContext
from pathlib import Path
from typing import TYPE_CHECKING

from nnql_swarm.learning import ahead
from nnql_swarm.world.rules_ahead import RULES
from nnql_swarm.protocol.jit import plain_python_environment
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.runfiles import EXIT_NO_SPACE, out_of_space
from nnql_swarm.transport.ports import wait_listening
from nnql_swarm.transport.settings import TransportSettings
from nnql_swarm.sim.supervisor import start_ignoring_sigint

if TYPE_CHECKING:
    from nnql_swarm.sim.resume import ResumePoint


PRELOADED = ("nnql_swarm.agent.agent_node", "nnql_swarm.recording.loggers", "setproctitle")
"""What the server the processes of a swarm are forked from imports, once (:func:`process_context`):
what an agent runs, and no more. A forked process starts with the server's memory, counted in its
resident memory: the world's modules (its rules, the shared table, the progress bar's tqdm) would
make every agent larger, so the one world imports them itself, once forked."""

SERVED = "nnql_swarm.launch.served"
"""Imported by the server after everything else: its ``__main__`` prepared, its memory tidied,
before it forks."""

MAIN_VARIABLE = "NNQL_SERVED_MAIN"
"""How the launcher tells the server its main module (:func:`main_to_serve`)."""

_SERVED: dict[str, str] | None = None
"""The environment the forkserver was started with (None: not started by this process yet)."""


def process_context() -> SpawnContext | ForkServerContext:
    """How a swarm's world and agents start: forked from one server process that imported what
    they run (multiprocessing's ``forkserver``, :data:`PRELOADED`), rather than each a fresh
    interpreter importing it all again (``spawn``): a process imports in about half a second of
    CPU, so 64 agents spawned on 2 cores took 10 to 20 s to start (docs/performance.md, "At
    scale"). The server holds no Zenoh session (a session has threads, which a fork does not
    carry) and runs the kernel uncompiled, as the processes do (``protocol.jit``); it is started
    here, with the environment now. A child of the server has the server's environment, not its
    launcher's: a launcher whose environment has changed since it started the server (a test
    setting a variable for one run) spawns its processes, as do systems without a forkserver.
    The kernels the processes run compiled ahead of time are first built where they are not yet
    (``learning.ahead``, ``world.rules_ahead``)."""
    global _SERVED
    for module in (ahead.KERNELS, RULES):
        module.ensure()
    os.environ.update(plain_python_environment())
    os.environ.update(main_to_serve())
    environment = dict(os.environ)
    if "forkserver" not in mp.get_all_start_methods() or _SERVED not in (None, environment):
        return mp.get_context("spawn")
    context = mp.get_context("forkserver")
    if _SERVED is None:
        context.set_forkserver_preload([__name__, *PRELOADED, SERVED])
        # The resource tracker first, on its own: starting it unblocks SIGINT, which a Ctrl-C
        # blocked meanwhile would reach while it is ignored, and be lost.
        resource_tracker.ensure_running()
        start_ignoring_sigint(forkserver.ensure_running)  # and so do its children
        _SERVED = environment
    return context


def main_to_serve() -> dict[str, str]:
    """The launcher's main module, as every child of the server would run it again before its
    target (multiprocessing's preparation: ``init_main_from_name`` or ``init_main_from_path``),
    for the server to run once instead (``launch.served``): a child that finds it in place skips
    it. Else each child ran it again from its source (no ``.pyc`` is written here): for a main
    run by name (``python -m bench.scale``), a fresh import of all it imports, 25 ms of CPU and
    its memory in every process; for one run from its path (``launch/swarm.py``, which imports
    nothing at its top), a compile and ``pkgutil``'s import, 0.3 MiB of every agent's memory."""
    data = spawn.get_preparation_data("server")
    if "init_main_from_name" in data:
        return {MAIN_VARIABLE: "name:" + data["init_main_from_name"]}
    if "init_main_from_path" in data:
        return {MAIN_VARIABLE: "path:" + data["init_main_from_path"]}
    return {}


def world_main(config: SwarmConfig, transport: TransportSettings, out: Path, record,
               progress: bool, start: "ResumePoint | None" = None,
               agent_wait_s: float | None = None) -> None:
    """The world process (spawned); ``record``: a RecordingPlan, True (to files) or False;
    ``start``: where it resumes (None: the run's start); ``agent_wait_s``: how long it waits
    for its agents (``--agent-wait``; None: ``world.world_machine.startup_timeout``)."""
    from nnql_swarm.recording.loggers import open_world_viz
    from nnql_swarm.sim.resume import ResumeError, ResumePoint, shared_table
    from nnql_swarm.launch.cli import episode_summary, progress as progress_bar
    from nnql_swarm.world.world_node import WorldOptions, run_world

    start = start or ResumePoint(0, 0)
    name_process("nnql-world", config)
    setup_logging("world")
    bar = progress_bar(config.episodes - start.episode, "episode") if progress else None
    collisions = 0

    def on_tick(world, report) -> None:
        nonlocal collisions
        collisions += len(report.collided)
        if viz is not None:
            viz.log_tick(world, report)
        if bar is not None and report.episode_row is not None:
            row = report.episode_row
            bar.set_postfix(**episode_summary(row, config.n_agents, config.lifelong),
                            collisions=collisions,
                            missed=row["missed_intents"],
                            ticks_per_s=f"{world.tick / max(time.monotonic() - started, 1e-9):.0f}",
                            refresh=False)
            bar.update(1)

    viz = open_world_viz(record, config, out)
    started = time.monotonic()
    try:
        try:
            table = shared_table(out, config, start)
        except ResumeError as error:
            logging.getLogger("nnql.world").error("%s", error)
            code = 1
        else:
            code = run_world(WorldOptions(config, transport, out, first_episode=start.episode,
                                          first_tick=start.tick, table=table,
                                          startup_timeout_s=agent_wait_s), on_tick,
                             None if viz is None else viz.before_row)
    except OSError as error:
        code = no_space_left(error, "world")
    finally:
        if bar is not None:
            bar.close()
        if viz is not None:
            viz.close()
    sys.exit(code)  # a spawned process's exit code is its target's SystemExit, not its return


def agent_main(agent: int, config: SwarmConfig, transport: TransportSettings, out: Path,
               resume: bool = False, recording=None, hub: tuple[str, int] | None = None,
               resume_episode: int | None = None, world_wait_s: float | None = None) -> None:
    """An agent process (spawned); ``resume`` reloads its checkpoint if there is one (the
    version of ``resume_episode``, or else the newest); ``hub``: the ``(host, port)`` of the
    world to wait for, where the agent is its client; ``world_wait_s``: how long a world that
    left may stay away (None: ``agent.agent_machine.WORLD_WAIT_S``)."""
    from nnql_swarm.agent.agent_node import AgentOptions, run_agent
    from nnql_swarm.recording.loggers import open_agent_viz

    name_process(f"nnql-agent {agent}", config)
    setup_logging(f"agent {agent}")
    if hub is not None:
        wait_listening(*hub, timeout_s=HUB_WAIT_S)  # if not, opening the session says so
    brain, on_episode_end, viz = open_agent_viz(recording, agent, config)
    try:
        waits = {} if world_wait_s is None else {"world_wait_s": world_wait_s}
        code = run_agent(AgentOptions(agent, config, transport, out, resume=resume,
                                      resume_episode=resume_episode, **waits), brain,
                         on_episode_end)
    except OSError as error:
        code = no_space_left(error, f"agent {agent}")
    finally:
        if viz is not None:
            viz.close()
    sys.exit(code)


def no_space_left(error: OSError, name: str) -> int:
    """The exit code of a process whose files could not be written for want of space, said in
    one line; any other error is raised again."""
    if not out_of_space(error):
        raise error
    logging.getLogger("nnql").error("no space left for the %s's files (%s); stopping", name,
                                    error.strerror or error)
    return EXIT_NO_SPACE


HUB_WAIT_S = 60.0
"""How long an agent of a hub topology waits for the world to listen before it tries anyway."""


def name_process(title: str, config: SwarmConfig) -> None:
    """Make the process recognisable in ps / pgrep: e.g. ``nnql-agent 3 <run-id>``; and make it
    end with the launcher (:func:`die_with_launcher`)."""
    import setproctitle

    setproctitle.setproctitle(f"{title} {config.run_id}")
    die_with_launcher()


PR_SET_PDEATHSIG = 1
"""prctl(2): the signal a process gets when the thread that started it ends."""


def die_with_launcher() -> None:
    """Have Linux send SIGTERM to this process when the launcher dies, even by ``kill -9``.

    Otherwise a launcher killed outright leaves its agents waiting for a world that never comes
    back, and they would join the next ``--resume`` of the same run as a second copy of each
    agent. SIGTERM stops a process as Ctrl-C does (checkpoints and stats intact). Elsewhere than
    Linux this does nothing.
    """
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(signal.SIGTERM))
    _let_go_of_the_server()
    parent = mp.parent_process()
    if (parent is not None and parent.pid is not None and os.getppid() != parent.pid
            and not _running(parent.pid)):
        os.kill(os.getpid(), signal.SIGTERM)  # it died before prctl took effect


def _let_go_of_the_server() -> None:
    """A process forked by the forkserver (:func:`process_context`) is the server's child: it
    gets its signal when the server ends, which the server does once every holder of the pipe
    that tells it its launcher lives has closed it. multiprocessing hands each child that pipe
    too (for children of its own, which ours never start): closed here, or the server, and so
    every process, would outlive a launcher killed outright."""
    server = forkserver._forkserver
    fd = getattr(server, "_forkserver_alive_fd", None)  # multiprocessing's own, set in a child
    if fd is not None:
        os.close(fd)
        setattr(server, "_forkserver_alive_fd", None)


def _running(pid: int) -> bool:
    """Whether process ``pid`` is still there. A process forked by the forkserver
    (:func:`process_context`) is the server's child, not the launcher's: the server ends with the
    launcher, and its children then get their signal."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def setup_logging(name: str) -> None:
    logging.basicConfig(level=os.environ.get("NNQL_LOG", "WARNING").upper(),
                        format=f"%(asctime)s {name}: %(message)s", stream=sys.stderr)
