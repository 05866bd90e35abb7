"""The last module the server of a swarm's processes imports (``launch.processes.PRELOADED``):
what the server leaves behind for its children, prepared and tidied once, before it forks them.

Every child runs its launcher's main module again before its target (multiprocessing's
preparation), unless it finds it in place; so the server runs it first, as a child would
(``launch.processes.main_to_serve`` names it).

A forked process starts with the server's memory as its own, page for page, until it writes to a
page. So the server collects its garbage and then freezes every object it holds
(``gc.freeze``): a child's collections never walk them, which would write to each object's
header and so copy every page of them into the child. It loads the agents' decision compiled
ahead of time (``learning.ahead``) for them too. And it hands the heap the import left free
back to the system (glibc's ``malloc_trim``), or every child would start with it resident.
"""

import ctypes
import ctypes.util
import gc
import os
from multiprocessing import process, spawn

from nnql_swarm.learning import ahead
from nnql_swarm.launch.processes import MAIN_VARIABLE


def serve_main() -> None:
    """Run the launcher's main module as ``__main__``, as each child would."""
    kind, _, main = os.environ.get(MAIN_VARIABLE, "").partition(":")
    if kind not in ("name", "path"):
        return
    current = process.current_process()
    setattr(current, "_inheriting", True)  # as multiprocessing marks a child that prepares
    try:
        if kind == "name":
            getattr(spawn, "_fixup_main_from_name")(main)
        else:
            spawn.import_main_path(main)
    finally:
        delattr(current, "_inheriting")


def tidy() -> None:
    gc.collect()
    gc.freeze()
    libc = ctypes.util.find_library("c")
    if libc is not None:
        trim = getattr(ctypes.CDLL(libc), "malloc_trim", None)
        if trim is not None:  # glibc's
            trim(0)


serve_main()
ahead.KERNELS.compiled("agent_decision")  # the agents' decision, loaded once for every child
tidy()
