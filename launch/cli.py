"""What every command-line entry point shares: one-line usage errors with exit code 2, ``--version``,
the command's name as it was called, the output folder made or refused in one line, the progress
bar of long work, and a word while the simulator compiles before that bar starts."""

import argparse
import math
import os
import shutil
import sys
import threading
import time
from importlib import metadata
from pathlib import Path
from typing import NoReturn

from tqdm import tqdm

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def package_version() -> str:
    """The installed version of the project (``pyproject.toml``'s)."""
    try:
        return metadata.version("nnql-swarm")
    except metadata.PackageNotFoundError:
        return "unknown (not installed)"


def _main_module() -> str | None:
    """The module run with ``python -m`` (None: a script or an installed command)."""
    spec = getattr(sys.modules.get("__main__"), "__spec__", None)
    return spec.name if spec is not None and spec.name != "__main__" else None


def program_name() -> str:
    """The command's name as it was called: ``nnql-swarm`` (an installed script), ``swarm.py``
    (a script of the checkout) or ``python -m nnql_swarm.launch.swarm``."""
    module = _main_module()
    return f"python -m {module}" if module else os.path.basename(sys.argv[0])


def invocation() -> list[str]:
    """The words that start this command again from the current directory: an installed script's
    name where it is on PATH, else the interpreter followed by the script or ``-m`` module."""
    module = _main_module()
    script = sys.argv[0]
    if module is None and not script.endswith(".py"):
        name = os.path.basename(script)
        found = shutil.which(name)
        if found and os.path.samefile(found, script):
            return [name]
        return [script]
    python = os.path.relpath(sys.executable)
    python = sys.executable if python.startswith("..") else python
    if os.sep not in python:  # an interpreter in the current directory
        python = "./" + python
    return [python, "-m", module] if module else [python, script]


class OneLineParser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line on stderr (no usage dump) and exit code 2, with
    ``--version``. Its name is the command's as it was called (:func:`program_name`)."""

    def __init__(self, *args, **kwargs) -> None:
        kwargs.setdefault("prog", program_name())
        super().__init__(*args, **kwargs)
        self.add_argument("--version", action="version",
                          version=f"%(prog)s (nnql-swarm {package_version()})")

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see --help)\n")


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that adds ``(default: X)`` to an option whose default is worth reading: not to a
    required option, an on/off flag, an option without a default (None, empty), nor one whose
    help already names its default; a tuple or list reads as its items, comma-separated."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        default = action.default
        if (action.required or not action.option_strings or action.nargs == 0
                or default is None or default is argparse.SUPPRESS
                or isinstance(default, bool) or default in ((), [], "")
                or "default" in text):
            return text
        shown = ",".join(map(str, default)) if isinstance(default, (tuple, list)) else str(default)
        return f"{text} (default: {shown.replace('%', '%%')})".lstrip()


PLAIN_INTERVAL_S = 5.0
"""Where stderr is not a terminal (CI logs, files), the bar is written at most this often."""


def progress(total: int, unit: str, desc: str = "") -> tqdm:
    """A progress bar on stderr: redrawn in place on a terminal; elsewhere a line of its own at
    most every few seconds, so that logs stay short and readable line by line. One process draws
    it, so its lock is a thread lock (tqdm's default adds a multiprocessing semaphore, which a
    process stopped by a signal leaves behind for the resource tracker to warn about)."""
    tqdm.set_lock(threading.RLock())
    if sys.stderr.isatty():
        return tqdm(total=total, unit=unit, desc=desc, file=sys.stderr, dynamic_ncols=True)
    return tqdm(total=total, unit=unit, desc=desc, file=_Lines(), mininterval=PLAIN_INTERVAL_S,
                ascii=True, ncols=100)


def episode_summary(row: dict, agents: int, lifelong: bool) -> dict[str, str]:
    """What a swarm's progress bar shows of an episode that ended (its ``episodes.csv`` row):
    the agents home, or in a lifelong run the goals reached a step."""
    if lifelong:
        return {"goals": str(row["goals"]), "throughput": f"{row['throughput']:.2f}"}
    return {"arrived": f"{row['arrived']}/{agents}"}


class _Lines:
    """stderr as a bar's stream where it is not a terminal: each redraw becomes a line."""

    def __init__(self) -> None:
        self.last = ""

    def write(self, text: str) -> None:
        line = text[1:].rstrip()
        done = line.split("[")[0]  # the count; closing redraws the last one with a later time
        if text.startswith("\r") and done != self.last:
            sys.stderr.write(line + "\n")
            self.last = done

    def flush(self) -> None:
        sys.stderr.flush()


def results_folder(parser, out: Path | None, default_name: str, results, force: bool,
                   plots: bool = False) -> Path:
    """The folder an experiment writes its ``results`` (file names) into, made where it is not
    there: ``out``, else ``runs/<default_name>-<date>-<time>``. Stops at the parser's one-line
    error where it is a file, already holds one of the results (unless ``force``), cannot be
    made, or ``plots`` are asked for without matplotlib."""
    if out is None:
        out = Path("runs") / time.strftime(f"{default_name}-%Y%m%d-%H%M%S")
    if out.exists() and not out.is_dir():
        parser.error(f"--out {out} exists and is not a directory")
    held = [name for name in results if (out / name).exists()]
    if held and not force:
        parser.error(f"{out} already holds results ({', '.join(held)}); pass --force to overwrite")
    if plots:
        from nnql_swarm.experiment.figures import require_matplotlib

        try:
            require_matplotlib()
        except RuntimeError as error:
            parser.error(str(error))
    try:
        os.makedirs(out, exist_ok=True)
    except FileExistsError:
        parser.error(f"--out {out} is a file, not a folder")
    except OSError as error:
        parser.error(f"cannot make the folder --out {out}: {error.strerror or error}")
    return out


COMPILING = "compiling the simulator (first run, about half a minute)..."


def prepare_simulator(world, run) -> None:
    """Compile or load the simulator before a progress bar starts (``sim.runs.warm_up``), so that
    the bar's first item, and its estimate of the time left, do not include it; says so when it
    compiles (its kernel is not in the on-disk cache, ``protocol.jit.cached``)."""
    from nnql_swarm.protocol.jit import cache_directory
    from nnql_swarm.sim.runs import compiled_simulator, warm_up

    cold = not compiled_simulator()
    if cold:
        print(COMPILING, file=sys.stderr, flush=True)
    started = time.monotonic()
    warm_up(world, run)
    if cold:
        print(f"compiled in {time.monotonic() - started:.0f} s; later runs load it from "
              f"{os.environ.get('NUMBA_CACHE_DIR', cache_directory())}", file=sys.stderr,
              flush=True)


def report_written(out: Path, elapsed: float) -> None:
    """The line an experiment ends with: where it wrote its files, and how long its simulation
    took (in milliseconds under a second: a small run of the compiled simulator takes a few)."""
    took = f"{elapsed * 1000:.0f} ms" if elapsed < 1 else f"{elapsed:.1f} s"
    print(f"wrote {out}/ in {took} of simulation")


def bounded(kind: type, low: float | None = None, high: float | None = None):
    """An argparse type: ``kind`` within ``[low, high]``."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a valid {kind.__name__}: {text!r}") from None
        if isinstance(value, float) and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
        if (low is not None and value < low) or (high is not None and value > high):
            bounds = f"at least {low}" if high is None else f"between {low} and {high}"
            raise argparse.ArgumentTypeError(f"must be {bounds}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def comma_choices(choices: tuple[str, ...], noun: str, fold_case: bool = False):
    """An argparse type: a comma-separated list of ``choices`` (``fold_case``: in any case), given
    back in the order of ``choices``."""

    def parse(text: str) -> tuple[str, ...]:
        names = [v.strip().lower() if fold_case else v.strip() for v in text.split(",")
                 if v.strip()]
        if not names or any(v not in choices for v in names):
            raise argparse.ArgumentTypeError(f"choose {noun} from {','.join(choices)}, got {text!r}")
        return tuple(v for v in choices if v in names)

    parse.__name__ = noun
    return parse


def parse_grid(text: str) -> tuple[int, int]:
    """``"11x11"`` -> ``(11, 11)``: a grid's width and height, each at least 1."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 11x11, not {text!r}") from None
    if width < 1 or height < 1:
        raise argparse.ArgumentTypeError(f"grid sides must be at least 1, got {text!r}")
    return width, height


def parse_workers(text: str) -> int | None:
    """``auto`` (None) or a positive number of worker processes."""
    return None if text == "auto" else bounded(int, 1)(text)


class Terminated(Exception):
    """SIGTERM arrived: stop like Ctrl-C, workers included."""


def raise_terminated(signum, frame):
    raise Terminated
