"""The last module the server of a swarm's processes imports (``launch.processes.PRELOADED``):
what the server leaves behind for its children, tidied once, before it forks them.

A forked process starts with the server's memory as its own, page for page, until it writes to a
page. So the server collects its garbage and then freezes every object it holds
(``gc.freeze``): a child's collections never walk them, which would write to each object's
header and so copy every page of them into the child. And it hands the heap the import left free
back to the system (glibc's ``malloc_trim``), or every child would start with it resident.

A child runs its launcher's main module again (multiprocessing's preparation); one run by name,
the server imported under that name (``launch.processes._launcher_main``), and runpy would warn
in every child that the module is there already, which is what the server meant.
"""

import ctypes
import ctypes.util
import gc
import warnings


def tidy() -> None:
    warnings.filterwarnings("ignore", category=RuntimeWarning, module="runpy",
                            message=".* found in sys.modules after import of package")
    gc.collect()
    gc.freeze()
    libc = ctypes.util.find_library("c")
    if libc is not None:
        trim = getattr(ctypes.CDLL(libc), "malloc_trim", None)
        if trim is not None:  # glibc's
            trim(0)


tidy()
