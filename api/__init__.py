"""nnQL swarm from Python: configure and run a swarm, read its episodes, Q-tables and recording,
and show it inline in Jupyter.

    from nnql_swarm.api import Swarm

    run = Swarm(agents=4, episodes=20, seed=1).run("runs/demo")   # in-process (fast)
    run.episodes                # one row per episode: a numpy structured array
    q_ds, q_ca = run.q_tables(0)
    run.show()                  # the Rerun viewer, inline in a notebook

The options are the command's (``launch/swarm.py --help``), by name: ``agents=8`` is
``--agents 8``, ``shared=False`` is ``--no-shared``, ``grid=(14, 12)`` is ``--grid 14x12``; a bad
one raises ValueError with the line the command prints. ``run(..., distributed=True)`` starts
the world and agent processes over Zenoh as the command does, and gives the same episodes and
Q-tables. docs/api.md has the whole of it.
"""

from nnql_swarm.api.python_api import (
    DETERMINISTIC_COLUMNS, EPISODE_DTYPE, Run, RunError, Swarm, open_run, resume, run,
)

__all__ = ["DETERMINISTIC_COLUMNS", "EPISODE_DTYPE", "Run", "RunError", "Swarm", "open_run",
           "resume", "run"]
