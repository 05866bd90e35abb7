"""Stop a swarm run at seeded moments, resume it, and compare it with the run left alone.

Each trial starts ``launch/swarm.py`` with the given options, stops it at a moment and in a way
drawn from the seed, continues it with ``--resume --out DIR`` until it completes, and compares
what it wrote with an uninterrupted run of the same options: the deterministic columns of
``episodes.csv`` and every checkpoint's Q-tables, exploration counter and generator state (and
the world's shared table with its pending records). The ways a run is stopped:

    int-launcher   SIGINT to the launcher alone (a service manager)
    int-group      SIGINT to the launcher's process group (Ctrl-C in a terminal)
    kill-group     SIGKILL to every process at once
    kill-launcher  SIGKILL to the launcher (its children stop as on SIGTERM)
    kill-world     SIGKILL to the world process (the launcher ends the run)

The moments are spread over the run by its progress, not by the clock, so that a busy machine
moves them with the run: the episodes are cut into equal spans, one episode drawn in each, and
the run is stopped a seeded fraction of a second after that episode's row appears; the first
span's moments fall in the processes' start-up and the first episodes (episode 0: a seeded time
after the launch, before any row).

    python -m tests.interruptions --moments 12 --seed 1
    python -m tests.interruptions --moments 12 --seed 1 -- --preset best-nnql

prints one line per trial and exits 1 if any resumed run differs. ``tests/test_resume.py`` runs
a few trials of each preset in the suite.
"""

import argparse
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nnql_swarm.transport import slotfile
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import find_process, group_pids, swarm_command

STOPS = ("int-launcher", "int-group", "kill-group", "kill-launcher", "kill-world")
RUN_TIMEOUT_S = 600


START_UP_S = 4.0
"""Trials of the first episode stop the run up to this long after its launch."""
WITHIN_EPISODE_S = 0.3
"""Other trials stop it up to this long after the row they wait for."""


@dataclass(frozen=True)
class Trial:
    """One interruption: once ``rows`` rows are written (0: from the launch), ``after_s``
    seconds later, and how."""

    rows: int
    after_s: float
    stop: str

    def __str__(self) -> str:
        when = "after the launch" if not self.rows else f"after row {self.rows}"
        return f"{self.stop:>13} {self.after_s:4.2f} s {when}"


@dataclass(frozen=True)
class Outcome:
    trial: Trial
    resumed_at: int | None  # the episode the first --resume started at (None: run was done)
    resumes: int
    difference: str | None  # None: the same run


def draw_trials(seed: int, count: int, episodes: int) -> list[Trial]:
    """``count`` moments, one in each equal span of the run's ``episodes``, each with a way to
    stop (every way once in each five trials, in a seeded order)."""
    rng = np.random.default_rng(seed)
    ways = [STOPS[k] for k in rng.permutation(len(STOPS))]
    trials = []
    for k in range(count):
        rows = int(rng.integers(k * episodes // count, max((k + 1) * episodes // count,
                                                            k * episodes // count + 1)))
        after = rng.uniform(0, START_UP_S if rows == 0 else WITHIN_EPISODE_S)
        trials.append(Trial(rows, round(float(after), 2), ways[k % len(ways)]))
    return trials


def run_left_alone(out: Path, options: list[str]) -> int:
    """Run the swarm to its end; returns how many episodes it played."""
    result = subprocess.run(swarm_command(out, *options), capture_output=True, text=True,
                            timeout=RUN_TIMEOUT_S)
    if result.returncode != 0:
        raise RuntimeError(f"the uninterrupted run failed: {result.stderr[-2000:]}")
    return rows_written(out)


def rows_written(out: Path) -> int:
    """The complete rows of ``out``'s ``episodes.csv`` so far (its header aside)."""
    try:
        return max((out / "episodes.csv").read_bytes().count(b"\n") - 1, 0)
    except FileNotFoundError:
        return 0


def stop_at(out: Path, options: list[str], trial: Trial, run_id: str) -> None:
    """Start the swarm and stop it as ``trial`` says (or let it end, if it ends first)."""
    swarm = subprocess.Popen(swarm_command(out, *options), stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + RUN_TIMEOUT_S
    while rows_written(out) < trial.rows and swarm.poll() is None and time.monotonic() < deadline:
        time.sleep(0.005)
    try:
        swarm.wait(timeout=trial.after_s)
        return  # it completed before the moment
    except subprocess.TimeoutExpired:
        pass
    if trial.stop == "int-launcher":
        swarm.send_signal(signal.SIGINT)
    elif trial.stop == "int-group":
        os.killpg(swarm.pid, signal.SIGINT)
    elif trial.stop == "kill-group":
        os.killpg(swarm.pid, signal.SIGKILL)
    elif trial.stop == "kill-launcher":
        swarm.kill()
    elif trial.stop == "kill-world":
        for pid in find_process(f"nnql-world {run_id}"):
            os.kill(pid, signal.SIGKILL)
    try:
        swarm.wait(timeout=60)
    finally:
        deadline = time.monotonic() + 30  # children of a killed launcher stop on their own
        while group_pids(swarm.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)


def resume_to_the_end(out: Path, options: list[str]) -> tuple[int | None, int]:
    """``--resume`` until the run is complete (or, stopped before it wrote its config, start it
    again as a user would); the episode the first resume started at."""
    first = None
    for resumes in range(1, 4):
        again = ["--resume"] if (out / "config.json").exists() else options
        result = subprocess.run(swarm_command(out, *again, "--no-progress"),
                                capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
        if result.returncode != 0:
            raise RuntimeError(f"--resume failed ({result.returncode}): {result.stderr[-2000:]}")
        if first is None:
            first = next((int(line.split(" at episode ")[1].split()[0])
                          for line in result.stderr.splitlines() if " at episode " in line), None)
        if "already complete" in result.stderr or "run finished" in result.stderr:
            return first, resumes
    raise RuntimeError("the run did not complete after 3 resumes")


def written(out: Path) -> tuple[list[tuple], dict[str, dict]]:
    """What a run wrote that must not depend on how it was stopped: the rows' deterministic
    columns, and each checkpoint's newest version (the run's end)."""
    rows = [tuple(row[f] for f in EPISODE_FIELDS) for row in read_episodes(out / "episodes.csv")]
    checkpoints = {path.name: slotfile.read(path)
                   for path in sorted((out / "checkpoints").glob("*.ckpt"))}
    return rows, checkpoints


def difference(expected: Path, got: Path) -> str | None:
    """How ``got`` differs from ``expected`` (None: it does not)."""
    rows_a, ckpt_a = written(expected)
    rows_b, ckpt_b = written(got)
    if rows_a != rows_b:
        first = next((k for k, (a, b) in enumerate(zip(rows_a, rows_b)) if a != b),
                     min(len(rows_a), len(rows_b)))
        return f"episodes.csv differs from episode {first} ({len(rows_b)} rows, {len(rows_a)} expected)"
    if sorted(ckpt_a) != sorted(ckpt_b):
        return f"checkpoint files {sorted(ckpt_b)}, expected {sorted(ckpt_a)}"
    for name, fields in ckpt_a.items():
        other = ckpt_b[name]
        for key, value in fields.items():
            if key == "run":  # the run's identity: each trial has a run id of its own
                continue
            same = (np.array_equal(value, other.get(key)) if isinstance(value, np.ndarray)
                    else value == other.get(key))
            if not same:
                return f"{name}: {key} differs"
    return None


def run_trials(work: Path, options: list[str], trials: list[Trial], expected: Path,
               report=print) -> list[Outcome]:
    """Each trial in its own directory under ``work``, compared with ``expected``."""
    outcomes = []
    for k, trial in enumerate(trials):
        out, run_id = work / f"trial-{k}", f"trial-{k}-{os.getpid()}"
        options_k = [*options, "--run-id", run_id]
        stop_at(out, options_k, trial, run_id)
        resumed_at, resumes = resume_to_the_end(out, options_k)
        outcome = Outcome(trial, resumed_at, resumes, difference(expected, out))
        report(f"{trial}: resumed at episode "
               f"{'-' if resumed_at is None else resumed_at}, "
               f"{outcome.difference or 'the same run'}")
        outcomes.append(outcome)
    return outcomes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tests.interruptions",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--moments", type=int, default=12, help="trials (default 12)")
    parser.add_argument("--seed", type=int, default=1, help="draws the moments (default 1)")
    parser.add_argument("--work", type=Path, default=Path("runs/interruptions"),
                        help="where the runs go (default runs/interruptions)")
    parser.add_argument("swarm_options", nargs="*",
                        help="options of launch/swarm.py after --, e.g. -- --preset best-nnql")
    args = parser.parse_args(argv)
    options = ["--no-record", *args.swarm_options]
    work = args.work / f"seed{args.seed}-{os.getpid()}"
    expected = work / "left-alone"
    episodes = run_left_alone(expected, [*options, "--run-id", "left-alone", "--no-progress"])
    print(f"left alone: {episodes} episodes; {args.moments} interruptions (seed {args.seed})")
    trials = draw_trials(args.seed, args.moments, episodes)
    outcomes = run_trials(work, options, trials, expected)
    same = sum(o.difference is None for o in outcomes)
    print(f"{same} of {len(outcomes)} resumed runs equal the run left alone")
    return 0 if same == len(outcomes) else 1


if __name__ == "__main__":
    sys.exit(main())
