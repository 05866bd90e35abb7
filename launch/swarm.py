#!/usr/bin/env python3
"""Start a swarm run: a world process and one process per agent, over Zenoh.

    python launch/swarm.py --agents 8

``--help`` lists the options; ``launch.swarm_cli`` is the command line. This file only calls it:
every process it spawns imports this file again (multiprocessing's spawn), and so loads nothing
it does not run.
"""

import sys

if __name__ == "__main__":
    from nnql_swarm.launch.swarm_cli import main

    sys.exit(main())
