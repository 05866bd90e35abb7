"""How the kernel runs: compiled by numba, or as the very same functions in plain Python.

Every model of the project (the learning step, the world's rules, whom an agent waits for) is
written once, as scalar numba-compatible Python over caller-provided buffers, and decorated with
:func:`kernel`. By default that compiles it: ``numba.njit(cache=True)``, without ``fastmath``, so
floating point follows IEEE 754 step by step and a compiled run equals a plain-Python run bit for
bit (the parity tests compare the distributed swarm, which runs plain Python, with the in-process
simulator, which runs compiled).

A process that sets ``NNQL_KERNEL=python`` before its first import runs the functions as written
and never imports numba: the swarm's agent and world processes do (the launcher sets it for its
children), since loading numba's LLVM would make each agent process several times larger and
slower to start.
Kernels group their buffers in named tuples (``learning.fields.LearnerBuffers``, ``Sight``,
``world.rules.Bodies``...). A compiled call that takes such tuples costs more than the body of a
small kernel, so the learner's per-decision kernels are :func:`inline_kernel`: numba compiles them
into each caller, and the tuples into plain values.
Kernel functions therefore only index and assign into their buffers, which may be numpy arrays
(compiled) or Python lists (plain: :func:`ints`, :func:`floats`, :func:`rows`, where reading a list
is several times faster), and never allocate on the hot path. The Q-tables are numpy arrays
either way (``learning.tables.Learner``): a decision reads a few of their rows, while a shared
table's updates write all over them, which in one compact array costs a cache line an entry.

numba's cache knows only the file of each compiled function, not those of the functions it calls:
an edited learner would leave a stale compiled simulator behind. So the cache lives in a directory
named by a digest of every kernel source (:func:`cache_directory`), unless ``NUMBA_CACHE_DIR``
says otherwise. Within it, numba knows a source by its content's digest, and each source folder
by its name (:class:`KernelCacheLocator`), not by its place on the disk: any checkout of the same
sources loads what another compiled.
"""

import functools
import hashlib
import os
from pathlib import Path
from typing import Union

import numpy as np

MODE_VARIABLE = "NNQL_KERNEL"
PLAIN = "python"

COMPILED = os.environ.get(MODE_VARIABLE, "compiled") != PLAIN
"""Whether kernel functions are compiled in this process (fixed at import)."""

KERNEL_ROOMS = ("learning", "protocol", "sim", "world")
"""The packages whose modules may define kernel functions."""


Buffer = Union[np.ndarray, list]
"""A kernel buffer, as the fields of the named tuples that group a kernel's arguments: an array
when compiled, a list when not."""


def cache_directory() -> Path:
    """Where compiled kernels are cached: one directory per version of the kernel sources."""
    root = Path(__file__).resolve().parent.parent
    digest = hashlib.sha256()
    for room in KERNEL_ROOMS:
        for path in sorted((root / room).glob("*.py")):
            source = path.read_bytes()
            if b"protocol.jit import" in source or path.name == "jit.py":
                digest.update(path.name.encode() + source)
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return cache / "nnql-swarm" / "kernels" / digest.hexdigest()[:16]


if COMPILED:
    import numba
    from numba import njit, prange

    from numba.core.caching import UserProvidedCacheLocator

    class KernelCacheLocator(UserProvidedCacheLocator):
        """numba's locator of ``NUMBA_CACHE_DIR``, keyed by what a source is rather than where:
        numba files a source under a folder named by the path of its folder on this disk, and
        takes it for changed when its time of change does; here the folder is named by its name
        alone (``learning``, ``sim``...), and a source is known by its content's digest. The
        directory is already one version of every kernel source (:func:`cache_directory`), so a
        second checkout of the same sources (a fresh clone, a worktree) loads what the first
        compiled, rather than compiling it again."""

        def __init__(self, py_func, py_file: str) -> None:
            super().__init__(py_func, py_file)
            self._source = Path(py_file)

        @classmethod
        def get_suitable_cache_subpath(cls, py_file: str) -> str:
            return Path(py_file).resolve().parent.name

        def get_source_stamp(self) -> str:
            return _source_digest(self._source)

    @functools.cache
    def _source_digest(path: Path) -> str:
        return hashlib.sha256(path.read_bytes()).hexdigest()

    # numba reads its environment once, at its own import, which may have come first
    numba.config.CACHE_DIR = os.environ.setdefault("NUMBA_CACHE_DIR", str(cache_directory()))
    numba.config.CACHE_LOCATOR_CLASSES = os.environ.setdefault(
        "NUMBA_CACHE_LOCATOR_CLASSES", f"{__name__}.{KernelCacheLocator.__name__}")

    def kernel(function):
        """Compile a kernel function (cached on disk beside its source)."""
        return njit(cache=True)(function)

    def inline_kernel(function):
        """Compile a kernel function into each caller (numba's ``inline="always"``)."""
        return njit(cache=True, inline="always")(function)

    def batch_kernel(function):
        """Compile a kernel function whose ``prange`` loops spread over the cores."""
        return njit(cache=True, parallel=True)(function)

else:
    from builtins import range as prange

    def kernel(function):
        """Plain Python: the function as written."""
        return function

    batch_kernel = inline_kernel = kernel


def cached(function) -> bool:
    """Whether calling a kernel function will not compile it: true in plain Python, and compiled
    when numba's on-disk index for it holds a compiled version of its current source (numba
    discards an index whose source file changed since). Compiled code that calls other kernel
    functions carries them inside, so the outermost function of a batch tells for all."""
    if not COMPILED:
        return True
    try:
        return bool(function._cache._cache_file._load_index())  # numba's own reading of its index
    except (AttributeError, OSError, EOFError, ValueError):
        return False


def ints(values) -> "np.ndarray | list[int]":
    """An integer buffer for kernel functions: an array when compiled, a list when not."""
    return np.array(values, dtype=np.int64) if COMPILED else list(values)


def floats(values) -> "np.ndarray | list[float]":
    return np.array(values, dtype=np.float64) if COMPILED else list(values)


def flags(values) -> "np.ndarray | list[bool]":
    return np.array(values, dtype=np.bool_) if COMPILED else list(values)


def rows(values: list[list[int]], width: int) -> "np.ndarray | list[list[int]]":
    """Rows of integers (such as the learner's neighbour rows) as a kernel buffer."""
    return np.array(values, dtype=np.int64).reshape(-1, width) if COMPILED else values


def python_values(buffer) -> list:
    """A buffer's values as Python numbers (for messages and files)."""
    return buffer.tolist() if isinstance(buffer, np.ndarray) else list(buffer)


def plain_python_environment() -> dict[str, str]:
    """``os.environ`` for a child process that must run the kernel uncompiled."""
    return {**os.environ, MODE_VARIABLE: PLAIN}
