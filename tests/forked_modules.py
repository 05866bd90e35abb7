"""A launcher, run by name (``python -m tests.forked_modules``) or from its path, that forks one
process as the swarm forks its agents (``launch.processes.process_context``) and prints, as one
JSON line, which of the modules named on its command line that process holds, whether the
child ran this module again as its ``__main__`` (multiprocessing's preparation) or found it run
by the server (``launch.served``), and how many objects it inherited frozen."""

import gc
import json
import os
import sys

RUN_BY = os.getpid()
"""The process that ran this module's code: as ``__main__``, the launcher; as ``__mp_main__``,
the server, or each child that prepares itself."""

from nnql_swarm.launch.processes import process_context


def held(names: list[str], queue) -> None:
    queue.put({"held": sorted(name for name in names if name in sys.modules),
               "main_run_again": sys.modules["__main__"].RUN_BY == os.getpid(),
               "frozen": gc.get_freeze_count()})


def main() -> None:
    context = process_context()
    queue = context.SimpleQueue()
    child = context.Process(target=held, args=(sys.argv[1:], queue))
    child.start()
    print(json.dumps(queue.get()))
    child.join()


if __name__ == "__main__":
    main()
