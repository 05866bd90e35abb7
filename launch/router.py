#!/usr/bin/env python3
"""A Zenoh router for swarms that span several hosts: the command
(``nnql_swarm.operations.router`` holds the work).

    python launch/router.py --listen tcp/0.0.0.0:7447
    python launch/router.py --zenoh-config secure/router.json5   # made by launch/secure.py
"""

import sys

from nnql_swarm.operations.router import main

if __name__ == "__main__":
    sys.exit(main())
