#!/usr/bin/env python3
"""Start a swarm run: a world process and one process per agent, over Zenoh.

    python launch/swarm.py --agents 8

``--help`` lists the options; ``launch.swarm_cli`` is the command line. This module only calls
it: every process the launcher spawns imports its main module again (multiprocessing's spawn),
this file or the ``nnql-swarm`` script, and so loads nothing it does not run.
"""

import signal
import sys


def main(argv: list[str] | None = None) -> int:
    heard: list[int] = []

    def interrupt(signum, frame):  # noted too: raised inside importlib, it would be swallowed
        heard.append(signum)
        raise KeyboardInterrupt

    signal.signal(signal.SIGINT, interrupt)
    try:
        from nnql_swarm.launch.swarm_cli import main as command_line

        if heard:
            raise KeyboardInterrupt
        return command_line(argv)
    except KeyboardInterrupt:  # before the run's own handlers: nothing was started yet
        print("\ninterrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
