#!/usr/bin/env python3
"""Start a swarm run: a world process and one process per agent, over Zenoh.

    python launch/swarm.py --agents 8

``--help`` lists the options; ``launch.swarm_cli`` is the command line. This module only calls
it: every process the launcher spawns imports its main module again (multiprocessing's spawn),
this file or the ``nnql-swarm`` script, and so loads nothing it does not run.
"""

import signal
import sys


class EarlyInterrupt:
    """SIGINT's handler until the run's own: raises KeyboardInterrupt wherever the launcher is,
    and notes that it did (:attr:`heard`). Raised inside importlib, or in a finalizer or a
    library's ``except BaseException``, the exception is swallowed; the note is not: the
    supervisor, taking over the signal, stops the run at once if it finds it
    (``sim.supervisor.Supervisor.run``)."""

    def __init__(self) -> None:
        self.heard = False

    def __call__(self, signum, frame):
        self.heard = True
        raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    interrupt = EarlyInterrupt()
    signal.signal(signal.SIGINT, interrupt)
    try:
        from nnql_swarm.launch.swarm_cli import main as command_line

        if interrupt.heard:
            raise KeyboardInterrupt
        return command_line(argv)
    except KeyboardInterrupt:  # before the run's own handlers: nothing was started yet
        print("\ninterrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
