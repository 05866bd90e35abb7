#!/usr/bin/env python3
"""Certificates, passwords and Zenoh configs for a secured swarm: the command
(``nnql_swarm.operations.secure`` holds the work).

    python launch/secure.py --out secure --agents 8 --router-host 192.0.2.1
"""

import sys

from nnql_swarm.operations.secure import main

if __name__ == "__main__":
    sys.exit(main())
