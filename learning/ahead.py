"""The swarm processes' kernels compiled ahead of time: extension modules that an agent or the
world imports without numba.

The swarm's processes run the kernel functions in plain Python (``protocol.jit``), since loading
numba and its LLVM would take an agent from some 40 MiB to 160. numba's ``pycc`` compiles
chosen functions, with fixed signatures, into an extension module that needs only numpy at run
time (:class:`AheadModule`: built into the kernel cache, ``protocol.jit.cache_directory``, one
directory per version of every kernel source, once per version, and found there). This module's
(:data:`KERNELS`) holds the per-observation kernels (:data:`EXPORTS`: an agent's decision,
``learning.decision.agent_decision``, its negotiation's plan, ``learning.plan.agent_plan``, an
observation's neighbours as the kernels read them, ``learning.plan.unpack_seen_into``, and its
neighbour rows, ``learning.neighbours.neighbour_rows_into``; the world's check of a
learning record, ``learning.expected.expected_record``, with every agent's plan of a tick at once,
``learning.plan.world_plans``, and the step that applies a tick's records to the shared table,
``learning.record.apply_records``; and the write of the shared table's updates into an agent's
copy, ``learning.record.write_entries``); the world's step has a module of its own
(``world.rules_ahead``). A process that does not find a module (not built yet, or built where no C
compiler was) runs its kernels in plain Python: the same functions, the same results, slower.

    python -m nnql_swarm.learning.ahead     # build it (the launcher does, where it is missing)

``NNQL_AHEAD=off`` (:data:`SWITCH`) makes a process run them in plain Python regardless.
"""

import contextlib
import fcntl
import functools
import importlib.machinery
import importlib.util
import logging
import os
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from types import ModuleType
from typing import Callable, Iterator

from nnql_swarm.learning.decision import SIGNATURE, agent_decision
from nnql_swarm.learning.expected import EXPECTED_SIGNATURE, expected_record
from nnql_swarm.learning.neighbours import ROWS_SIGNATURE, neighbour_rows_into
from nnql_swarm.learning.plan import (
    PLAN_SIGNATURE, UNPACK_SIGNATURE, WORLD_PLANS_SIGNATURE, agent_plan, unpack_seen_into,
    world_plans,
)
from nnql_swarm.learning.record import APPLY_SIGNATURE, WRITE_SIGNATURE, apply_records, write_entries
from nnql_swarm.protocol.jit import COMPILED, MODE_VARIABLE, cache_directory

log = logging.getLogger(__name__)

MODULE = "nnql_ahead_kernels"
"""The extension module's name (it is imported under this name, from the kernel cache)."""

EXPORTS: dict[str, tuple[Callable, str]] = {
    "agent_decision": (agent_decision, SIGNATURE),
    "agent_plan": (agent_plan, PLAN_SIGNATURE),
    "unpack_seen_into": (unpack_seen_into, UNPACK_SIGNATURE),
    "neighbour_rows_into": (neighbour_rows_into, ROWS_SIGNATURE),
    "expected_record": (expected_record, EXPECTED_SIGNATURE),
    "apply_records": (apply_records, APPLY_SIGNATURE),
    "world_plans": (world_plans, WORLD_PLANS_SIGNATURE),
    "write_entries": (write_entries, WRITE_SIGNATURE),
}
"""Each kernel the module holds, by name: the function and its signature."""

PLAIN, AHEAD, JIT = "python", "ahead-of-time", "numba"
"""How this process runs a kernel compiled ahead of time (:meth:`AheadModule.compiled`): in plain
Python, by the module compiled ahead of time, or compiled by numba (a process that runs the
kernels compiled)."""

SWITCH = "NNQL_AHEAD"
"""``NNQL_AHEAD=off`` in a process's environment: it runs the kernels of every :class:`AheadModule`
in plain Python even where it is built (to compare the two, ``bench.paired --a-env
NNQL_AHEAD=off``)."""


class AheadModule:
    """One extension module of kernels compiled ahead of time: its name, the kernels it holds
    (``exports``: by name, the function and its signature), the module that builds it when run
    with ``python -m`` (``builder``), and what it holds, in words (``holds``, said when it is
    built). Built into the kernel cache once per version of the kernel sources."""

    def __init__(self, name: str, exports: dict[str, tuple[Callable, str]], builder: str,
                 holds: str) -> None:
        self.name, self.exports, self.builder, self.holds = name, exports, builder, holds
        self._kernels: dict[str, tuple[Callable, str]] = {}

    def path(self) -> Path:
        """Where the module of the current kernel sources is, or is to be built."""
        return cache_directory() / (self.name + importlib.machinery.EXTENSION_SUFFIXES[0])

    def load(self) -> ModuleType | None:
        """The module of the current kernel sources, if it was built (None otherwise, or if it
        cannot be loaded, which is logged)."""
        path = self.path()
        if not path.exists():
            return None
        try:
            spec = importlib.util.spec_from_file_location(self.name, path)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(module)
        except ImportError as error:
            log.warning("the kernels compiled ahead of time cannot be loaded (%s); "
                        "running them in plain Python", error)
            return None
        return module

    def compiled(self, name: str) -> tuple[Callable, str]:
        """The kernel ``name`` of :attr:`exports`, as this process runs it, and how
        (:data:`PLAIN`, :data:`AHEAD`, :data:`JIT`). Looked up once."""
        found = self._kernels.get(name)
        if found is None:
            function = self.exports[name][0]
            if COMPILED:
                found = function, JIT
            elif self._module is None:
                found = function, PLAIN
            else:
                found = getattr(self._module, name), AHEAD
            self._kernels[name] = found
        return found

    @functools.cached_property
    def _module(self) -> ModuleType | None:
        """The module as this process uses it, looked for once: None where it is not built,
        or switched off (:data:`SWITCH`)."""
        return None if os.environ.get(SWITCH) == "off" else self.load()

    def build(self) -> Path:
        """Compile the module into the kernel cache, unless it is there; its path. Needs numba,
        so a process that runs the kernels compiled."""
        if not COMPILED:
            raise RuntimeError(f"building ahead of time needs numba: run it with "
                               f"{MODE_VARIABLE} unset")
        target = self.path()
        target.parent.mkdir(parents=True, exist_ok=True)
        with _locked(target.parent, self.name):
            if target.exists():
                return target
            with warnings.catch_warnings():  # pycc is pending deprecation in numba, and says so
                warnings.simplefilter("ignore")
                from numba.pycc import CC
            with tempfile.TemporaryDirectory(dir=target.parent) as scratch:
                cc = CC(self.name, source_module=self.builder)
                cc.output_dir = scratch
                for name, (function, signature) in self.exports.items():
                    cc.export(name, signature)(getattr(function, "py_func"))
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    cc.compile()
                os.replace(Path(scratch) / cc.output_file, target)
        return target

    def failure_path(self) -> Path:
        """Where a failed build of the current kernel sources says why: none is tried again."""
        return self.path().with_suffix(".failed")

    def ensure(self) -> bool:
        """Build the module where it is missing, in a child process that loads numba (this one
        need not), saying so; whether it is there. A failed build is logged, and noted beside it
        (:meth:`failure_path`), so that no later process tries it again; the processes run the
        kernels in plain Python."""
        if self.path().exists():
            return True
        failed = self.failure_path()
        if failed.exists():
            return False
        print(f"Compiling {self.holds} ahead of time (once per version of the kernel sources; "
              f"some 20 s)...", file=sys.stderr, flush=True)
        env = {**os.environ, MODE_VARIABLE: "compiled"}
        done = subprocess.run([sys.executable, "-m", self.builder], env=env,
                              capture_output=True, text=True)
        if done.returncode != 0 or not self.path().exists():
            failed.parent.mkdir(parents=True, exist_ok=True)
            failed.write_text(done.stderr)
            log.warning("%s could not be compiled ahead of time, so they run in plain Python "
                        "(why: %s; delete it to try again)", self.holds, failed)
            return False
        return True


@contextlib.contextmanager
def _locked(directory: Path, name: str) -> Iterator[None]:
    """Hold a module's build lock in the cache directory: processes that build it at once build
    it once."""
    with open(directory / (name + ".lock"), "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


KERNELS = AheadModule(MODULE, EXPORTS, __name__, "the agents' and the world's kernels")
"""The module of :data:`EXPORTS`."""


if __name__ == "__main__":
    print(KERNELS.build())
