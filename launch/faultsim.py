#!/usr/bin/env python3
"""Run seeded fault schedules of the swarm in the deterministic simulator, and check each.

    python launch/faultsim.py --schedules 10000 --seed-base 0 [--agents 8]

Schedule ``i`` is drawn from seed ``seed-base + i`` (``sim.schedule``): a small run (2 or 3
episodes of a few steps) with latency, drops, duplicates, reordering, partitions, stalls and
crashes; ``sim.checks`` says what each run must satisfy, and a run with benign faults only must
equal ``--in-process`` bit for bit (``sim.parity``). A failing schedule prints its seed, what
failed, and the command that reproduces it exactly (``--seed-base SEED --schedules 1``; add
``--verbose`` for its faults). The last line is ``N schedules, K failures``; the exit code is 0
only if K is 0 (2 for a bad option).

Schedules are split over ``--workers`` processes (multiprocessing ``spawn``) in chunks taken in
seed order; a schedule's result depends on its seed alone, so the split changes nothing.
"""

import argparse
import contextlib
import gc
import multiprocessing as mp
import os
import shutil
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Callable, NamedTuple

from nnql_swarm.launch.cli import DefaultsHelpFormatter, OneLineParser, progress
from nnql_swarm.protocol.jit import plain_python_environment

CHUNK = 25
"""Schedules a worker runs per task."""

MAX_SIM_AGENTS = 64
MAX_SEED = 2**63


class Result(NamedTuple):
    """One schedule's result, as a worker sends it back."""

    seed: int
    failures: tuple[str, ...]
    digest: str
    ticks: int
    events: int
    virtual_s: float
    fired: tuple[str, ...] = ()  # the kinds of the faults that hit it


def check_schedule(seed: int, agents: int, scratch: Path | None = None,
                   verbose: bool = False) -> Result:
    """Draw, run and check the schedule of ``seed``; never raises (a raise is a failure)."""
    from nnql_swarm.sim.parity import parity_failures
    from nnql_swarm.sim.schedule import draw_schedule
    from nnql_swarm.sim.distributed import run_schedule

    try:
        schedule = draw_schedule(seed, agents)
        if verbose:
            print("\n".join(schedule.describe()), file=sys.stderr)
        outcome = run_schedule(schedule, scratch, fingerprints=schedule.benign)
        failures = list(outcome.failures)
        if schedule.benign and not failures:
            assert outcome.fingerprints is not None, "a benign schedule's run keeps them"
            failures += parity_failures(schedule.config, outcome.rows, outcome.fingerprints,
                                        scratch)
        return Result(seed, tuple(failures), outcome.digest, outcome.ticks, outcome.events,
                      outcome.virtual_s, outcome.fired)
    except Exception as error:  # noqa: BLE001 - a bug the schedule found: report it with its seed
        where = traceback.extract_tb(error.__traceback__)[-1]
        return Result(seed, (f"raised {type(error).__name__}: {error} "
                             f"({Path(where.filename).name}:{where.lineno})",), "-", 0, 0, 0.0)


_SCRATCH: Path | None = None


def _scratch() -> Path:
    """A worker's directory for checkpoints, in memory where the system has one."""
    global _SCRATCH
    if _SCRATCH is None:
        shm = Path("/dev/shm")
        base = shm if shm.is_dir() and os.access(shm, os.W_OK) else None
        _SCRATCH = Path(tempfile.mkdtemp(prefix="nnql-faultsim-", dir=base))
        import atexit

        atexit.register(shutil.rmtree, _SCRATCH, True)
    return _SCRATCH


def _worker_setup() -> None:
    """A worker process runs schedule after schedule, each some ten thousand objects that live
    as long as it does (the brains' tables are lists): the cyclic garbage collector, which would
    go through them again and again while they live, runs once after each schedule instead,
    and never through what the imports made."""
    import nnql_swarm.sim.parity  # noqa: F401 - imported before the freeze
    import nnql_swarm.sim.distributed  # noqa: F401

    gc.freeze()
    gc.disable()


def _run_chunk(task: tuple[list[int], int]) -> list[Result]:
    seeds, agents = task
    scratch = _scratch()
    results = []
    for seed in seeds:
        results.append(check_schedule(seed, agents, scratch))
        if not gc.isenabled():
            gc.collect()
    return results


@contextlib.contextmanager
def plain_python():
    """Workers started within run the kernel uncompiled, as the swarm's processes do (and, with
    the brains' tables as lists, faster than a compiled call per step from Python)."""
    saved = dict(os.environ)
    os.environ.update(plain_python_environment())
    try:
        yield
    finally:
        os.environ.clear()
        os.environ.update(saved)


def run_schedules(count: int, seed_base: int, agents: int = 8, workers: int = 2,
                  on_done: Callable[[list[Result]], None] | None = None) -> list[Result]:
    """Run schedules ``seed_base .. seed_base + count - 1``; their results in seed order.
    ``on_done(results)`` is called as each chunk of schedules completes."""
    seeds = list(range(seed_base, seed_base + count))
    chunks = [(seeds[i:i + CHUNK], agents) for i in range(0, count, CHUNK)]
    results: list[Result] = []
    if workers <= 1 or len(chunks) == 1:
        for chunk in chunks:
            chunk_results = _run_chunk(chunk)
            results.extend(chunk_results)
            if on_done is not None:
                on_done(chunk_results)
        return results
    with plain_python(), mp.get_context("spawn").Pool(workers, initializer=_worker_setup) as pool:
        for chunk_results in pool.imap(_run_chunk, chunks):
            results.extend(chunk_results)
            if on_done is not None:
                on_done(chunk_results)
    return results


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(description=__doc__.split("\n\n")[0],
                      formatter_class=DefaultsHelpFormatter)
    p.add_argument("--schedules", type=int, default=1000, help="how many schedules to run")
    p.add_argument("--seed-base", type=int, default=0, help="the first schedule's seed")
    p.add_argument("--agents", type=int, default=8, help="agents per schedule")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1),
                   help="processes to run them in")
    p.add_argument("--verbose", action="store_true",
                   help="print each schedule's faults and result (meant for a few)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.schedules < 1:
        parser.error(f"--schedules must be at least 1, not {args.schedules}")
    if not 0 <= args.seed_base < MAX_SEED:
        parser.error(f"--seed-base must be 0 .. 2**63 - 1, not {args.seed_base}")
    if args.seed_base + args.schedules > MAX_SEED:
        parser.error("--seed-base + --schedules must stay below 2**63")
    if not 1 <= args.agents <= MAX_SIM_AGENTS:
        parser.error(f"--agents must be 1..{MAX_SIM_AGENTS}, not {args.agents}")
    if args.workers < 1:
        parser.error(f"--workers must be at least 1, not {args.workers}")
    bar = None if args.no_progress or args.verbose else progress(args.schedules, "schedule")
    started = time.monotonic()
    if args.verbose:
        results = [check_schedule(seed, args.agents, verbose=True)
                   for seed in range(args.seed_base, args.seed_base + args.schedules)]
        for r in results:
            print(f"schedule {r.seed}: {'FAILED' if r.failures else 'passed'}, {r.ticks} ticks, "
                  f"{r.events} events, {r.virtual_s:.3f} virtual s, digest {r.digest}",
                  file=sys.stderr)
    else:
        failed = 0

        def done(chunk: list[Result]) -> None:
            nonlocal failed
            failed += sum(1 for r in chunk if r.failures)
            if bar is not None:
                bar.set_postfix(failures=failed, refresh=False)
                bar.update(len(chunk))

        results = run_schedules(args.schedules, args.seed_base, args.agents, args.workers, done)
        if bar is not None:
            bar.close()
    failures = [r for r in results if r.failures]
    for r in failures:
        print(f"schedule {r.seed} FAILED (digest {r.digest}): {r.failures[0]}")
        for line in r.failures[1:]:
            print(f"  {line}")
        print(f"  reproduce: python launch/faultsim.py --seed-base {r.seed} --schedules 1 "
              f"--agents {args.agents} --verbose")
    elapsed = time.monotonic() - started
    ticks = sum(r.ticks for r in results)
    events = sum(r.events for r in results)
    print(f"{elapsed:.1f} s, {args.workers if not args.verbose else 1} worker(s), {ticks} ticks, "
          f"{events} events", file=sys.stderr)
    print(f"{len(results)} schedules, {len(failures)} failures")
    return 0 if not failures else 1


if __name__ == "__main__":
    sys.exit(main())
