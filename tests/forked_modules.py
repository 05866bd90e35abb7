"""A launcher run by name (``python -m tests.forked_modules``) that forks one process as the swarm
forks its agents (``launch.processes.process_context``) and prints, as one JSON line, which of
the modules named on its command line that process holds, and whether it holds this module
under its own name (imported by the server, not again by the child), and how many objects it
inherited frozen (``launch.served``)."""

import gc
import json
import sys

from nnql_swarm.launch.processes import process_context


def held(names: list[str], queue) -> None:
    queue.put({"held": sorted(name for name in names if name in sys.modules),
               "main_by_name": "tests.forked_modules" in sys.modules,
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
