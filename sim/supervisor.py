"""Keeps a swarm's processes running: starts them, restarts agents that die, stops them all.

An agent that exits while the world still runs (killed, crashed) is restarted after a backoff
(0.5 s, doubling up to 8 s; reset once it has lived 30 s) with ``resume=True``, so it reloads its
last checkpoint and rejoins at the next tick; one that stopped because its world was gone for
too long (``EXIT_NO_WORLD``) is not. The world is not restarted: it owns the run's
files, so a dead world ends the run and ``--resume`` continues it. Stopping (Ctrl-C, SIGTERM)
sends SIGTERM to every child, waits a grace period, then kills what is left.
"""

import logging
import signal
import time
from dataclasses import dataclass, field
from multiprocessing.context import ForkServerContext, SpawnContext
from multiprocessing.process import BaseProcess
from typing import Callable

from nnql_swarm.transport.runfiles import EXIT_NO_SPACE
from nnql_swarm.transport.settings import EXIT_NO_WORLD, EXIT_TRANSPORT

log = logging.getLogger("nnql.supervisor")

POLL_S = 0.1
SHUTDOWN_GRACE_S = 2.0
"""Children get this long to exit by themselves before they are killed."""
BACKOFF_FIRST_S = 0.5
BACKOFF_MAX_S = 8.0
HEALTHY_AFTER_S = 30.0
FATAL_EXIT_CODES = {EXIT_TRANSPORT: "could not start", EXIT_NO_SPACE: "had no space left"}
"""The exit codes of a child that restarting would not help, and what each says."""
FATAL_GRACE_S = 1.5
"""After one child could not start, the others get this long to fail the same way and say so
(every process that cannot reach Zenoh prints its own line) before the run is stopped."""


@dataclass
class Child:
    """One supervised process; ``make_args(restarted)`` gives its target's arguments."""

    name: str
    target: Callable
    make_args: Callable[[bool], tuple]
    restartable: bool
    process: BaseProcess | None = None
    started_at: float = 0.0
    restarts: int = 0
    failures_in_a_row: int = 0
    restart_at: float | None = None
    exit_codes: list[int] = field(default_factory=list)

    @property
    def started(self) -> BaseProcess:
        """Its process: every child is started before it is supervised."""
        assert self.process is not None, f"{self.name} was never started"
        return self.process


class Supervisor:
    """Runs children until the leader (the world, or else every agent) is done."""

    def __init__(self, context: SpawnContext | ForkServerContext) -> None:
        self.context = context
        self.children: list[Child] = []
        self.stop_requested = False
        self.fatal: Child | None = None

    def add(self, name: str, target: Callable, make_args: Callable[[bool], tuple],
            restartable: bool) -> Child:
        child = Child(name, target, make_args, restartable)
        self.children.append(child)
        return child

    def request_stop(self, *_signal) -> None:
        """Signal handler: stop everything at the next poll."""
        self.stop_requested = True

    def run(self, leader: Child | None, on_poll: Callable[[], bool | None] | None = None) -> int:
        """Start every child and supervise; returns the leader's exit code (130 on a stop).
        ``on_poll()`` is called at every poll (every :data:`POLL_S`); a true result stops the run
        as Ctrl-C does. A SIGINT handler found in place whose ``heard`` is true (the launcher's
        first, ``launch/swarm.py``) counts as a Ctrl-C already."""
        previous = {s: signal.signal(s, self.request_stop) for s in (signal.SIGINT, signal.SIGTERM)}
        if getattr(previous[signal.SIGINT], "heard", False):
            self.stop_requested = True  # a Ctrl-C the launcher's first handler heard was swallowed
        try:
            for child in self.children:
                if self.stop_requested:
                    break
                self._start(child, restarted=False)
            while not self.stop_requested:
                if self._leader_done(leader) or self._fatal_exit():
                    break
                self._restart_dead_agents(leader)
                if on_poll is not None and on_poll():
                    self.stop_requested = True
                    break
                time.sleep(POLL_S)
            if self.fatal is not None:
                self._let_the_others_report()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)
        if self.stop_requested:
            self.stop_all(signal_first=True)
            return 130
        if self.fatal is not None:
            code = self.fatal.started.exitcode
            log.error("%s %s (%s); stopping the run", self.fatal.name,
                      FATAL_EXIT_CODES.get(code or 0, "failed"), describe_exit(code))
            self.stop_all(signal_first=True)
            return code if code is not None else 1
        leader_code = leader.started.exitcode if leader is not None else None
        leader_failed = leader is not None and leader_code != 0
        if leader is not None and leader_failed:
            log.error("%s exited (%s)", leader.name, describe_exit(leader_code))
        self.stop_all(signal_first=leader_failed)
        if leader is not None:
            return leader_code if leader_code is not None else 1
        return max((abs(c.started.exitcode or 0) for c in self.children), default=0)

    def _let_the_others_report(self) -> None:
        """Give the other children :data:`FATAL_GRACE_S` to fail the same way and say so."""
        deadline = time.monotonic() + FATAL_GRACE_S
        while (any(c.started.is_alive() for c in self.children)
               and time.monotonic() < deadline and not self.stop_requested):
            time.sleep(POLL_S)

    def _fatal_exit(self) -> Child | None:
        """A child that cannot work at all (e.g. no Zenoh session): restarting would not help."""
        for child in self.children:
            code = child.started.exitcode
            if code is not None and code in FATAL_EXIT_CODES:
                self.fatal = child
                return child
        return None

    def _leader_done(self, leader: Child | None) -> bool:
        if leader is not None:
            return not leader.started.is_alive()
        return all(not c.started.is_alive() and c.started.exitcode in (0, EXIT_NO_WORLD)
                   for c in self.children)

    def _start(self, child: Child, restarted: bool) -> None:
        process = self.context.Process(
            target=child.target, name=child.name, args=child.make_args(restarted)
        )
        child.process = process
        if isinstance(self.context, ForkServerContext):  # forked by a server that ignores it
            process.start()  # (and may first finish its imports: Ctrl-C must not be ignored)
        else:
            start_ignoring_sigint(process.start)
        child.started_at = time.monotonic()
        child.restart_at = None

    def _restart_dead_agents(self, leader: Child | None) -> None:
        now = time.monotonic()
        for child in self.children:
            if not child.restartable or child.started.is_alive():
                continue
            code = child.started.exitcode
            if code in (0, EXIT_NO_WORLD):
                continue  # told by the world that the run is over, or the world is gone
            if child.restart_at is None:
                assert code is not None, "a process that is not alive has exited"
                child.exit_codes.append(code)
                lived = now - child.started_at
                child.failures_in_a_row = 1 if lived > HEALTHY_AFTER_S else child.failures_in_a_row + 1
                delay = min(BACKOFF_FIRST_S * 2 ** (child.failures_in_a_row - 1), BACKOFF_MAX_S)
                child.restart_at = now + delay
                log.warning("%s exited (%s) after %.1f s; restarting in %.1f s",
                            child.name, describe_exit(code), lived, delay)
            elif now >= child.restart_at:
                child.restarts += 1
                self._start(child, restarted=True)

    def restarted(self) -> dict[str, list[str]]:
        """Every child restarted so far, with how each exit that it was restarted after
        ended (``describe_exit``)."""
        return {child.name: [describe_exit(code) for code in child.exit_codes[:child.restarts]]
                for child in self.children if child.restarts}

    def stop_all(self, signal_first: bool) -> None:
        """Let children exit (after SIGTERM if ``signal_first``); kill those still there."""
        alive = [c.process for c in self.children if c.process is not None]
        if signal_first:
            for process in alive:
                if process.is_alive():
                    process.terminate()
        deadline = time.monotonic() + SHUTDOWN_GRACE_S
        for process in alive:
            process.join(max(0.0, deadline - time.monotonic()))
        for process in alive:
            if process.is_alive():
                if not signal_first:
                    process.terminate()
                    process.join(0.3)
                if process.is_alive():
                    process.kill()
                    process.join()


def describe_exit(code: int | None) -> str:
    if code is None:
        return "still running"
    if code < 0:
        try:
            return f"killed by {signal.Signals(-code).name}"
        except ValueError:
            return f"killed by signal {-code}"
    return f"exit code {code}"


def start_ignoring_sigint(start: Callable[[], None]) -> None:
    """``start()`` a child process that starts with SIGINT ignored (a disposition exec and fork
    keep), until its node takes the signal (``world.world_node``, ``agent.agent_node``): a Ctrl-C while it
    still starts up would raise in the middle of an import and print a traceback; the launcher
    stops it then (SIGTERM). The forkserver the children are forked from starts so too
    (``launch.processes.process_context``), and hands it on. Here the signal is blocked meanwhile
    (Linux keeps a blocked signal pending, ignored or not), so a Ctrl-C that comes now reaches
    this process's handler after."""
    held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    _run_pending_handlers()
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        start()
    finally:
        signal.signal(signal.SIGINT, handler)
        signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _run_pending_handlers() -> None:
    """Nothing, in Python: entering a Python function runs the Python handlers of the signals
    already caught. A Ctrl-C caught just before SIGINT is set to be ignored would otherwise be
    dropped (CPython runs a caught signal's handler later, and skips it if it is ignored by then)."""
