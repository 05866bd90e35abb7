#!/usr/bin/env python3
"""Two source trees' figures of one benchmark, run alternately: the least of each figure in each.

A shared machine's speed drifts by a fifth within minutes, more than most changes to the
handlers save; runs of two trees compare only when they are made together, and each figure is
best read as the least it took, since the drift and other processes only ever add to a cost.

    python -m bench.alternately --a-dir /tmp/before --rounds 8 \\
        -- bench.agent_parts --agents 8 --episodes 10 --repeats 2
    python -m bench.alternately --a-dir /tmp/before --rounds 6 \\
        -- bench.node_cpu --agents 8 --episodes 10 --repeats 3 --cpu-time

Each round runs the benchmark module after ``--`` once in each tree, A first in odd rounds and
B first in even ones. Every line of its output that starts with words and holds numbers with a
decimal point is a figure, named by the words; its value in a run is the least of those numbers
(the benchmark's repeats; or their median and the repeats). Printed for each figure: the least
value in each tree and B's over A's, the same of the medians, and every run's value. For costs
(microseconds), not rates. Where the host is busy, the least of a few runs can rest on one lucky
run: a run of one tree against itself (the same code in both) gave 1.15 at 8 agents with the host
busy (8 December at 00:30). Trust a ratio whose runs' spread is small, and whose medians agree.

Each tree runs its own code: the benchmark runs in the tree with ``PYTHONPATH`` on it, where its
``nnql_swarm`` package is (checked before the first round), and its kernels compiled ahead of
time are built first where they are missing, as the launcher would build them: otherwise a
tree's processes run them in plain Python.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

from nnql_swarm.protocol.jit import MODE_VARIABLE

ROOT = Path(__file__).resolve().parent.parent
FIGURE = re.compile(r"^\s*([A-Za-z][^\d]*?)\s+\(?-?\d")
DECIMAL = re.compile(r"(?<![\w.])-?\d+\.\d+(?![\w.])")
BUILDERS = ("nnql_swarm.learning.ahead", "nnql_swarm.world.rules_ahead")
"""The modules that build a tree's kernels compiled ahead of time (``learning.ahead``)."""


def figures(output: str) -> dict[str, float]:
    """Each figure of a benchmark's output and its value (the least decimal number of its line)."""
    found = {}
    for line in output.splitlines():
        match = FIGURE.match(line)
        numbers = [float(n) for n in DECIMAL.findall(line[match.end(1):])] if match else []
        if numbers:
            found[" ".join(match.group(1).split())] = min(numbers)
    return found


def run(tree: Path, command: list[str], compiled: bool = False) -> str:
    """``python -m <command>`` in ``tree``, on its own code; its output (a failure ends it all).
    ``compiled``: with the kernels compiled by numba, whatever this process was told."""
    env = {**os.environ, "PYTHONPATH": str(tree)}
    if compiled:
        env.pop(MODE_VARIABLE, None)
    done = subprocess.run([sys.executable, "-m", *command], cwd=tree, capture_output=True,
                          text=True, env=env)
    if done.returncode != 0:
        last = done.stderr.strip().splitlines()[-1:] or ["no output"]
        raise SystemExit(f"alternately.py: {' '.join(command)} failed in {tree}: {last[0]}")
    return done.stdout


def prepare(tree: Path) -> None:
    """Check that ``tree`` runs its own ``nnql_swarm``, and build its kernels where missing."""
    done = subprocess.run([sys.executable, "-c", "import nnql_swarm; print(nnql_swarm.__file__)"],
                          cwd=tree, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(tree)})
    package = Path(done.stdout.strip() or "?").resolve()
    if done.returncode != 0 or tree.resolve() not in package.parents:
        raise SystemExit(f"alternately.py: {tree} does not hold the nnql_swarm it would run "
                         f"({package})")
    for builder in BUILDERS:  # they compile with numba
        run(tree, [builder], compiled=True)


def main() -> int:
    argv = sys.argv[1:]
    command = argv[argv.index("--") + 1:] if "--" in argv else []
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--a-dir", type=Path, required=True, help="the tree before (A)")
    p.add_argument("--b-dir", type=Path, default=ROOT, help="the tree after (B; default: this one)")
    p.add_argument("--rounds", type=int, default=6, help="runs in each tree (default 6)")
    args = p.parse_args(argv[:argv.index("--")] if "--" in argv else argv)
    if not command:
        p.error("name the benchmark after --, e.g. -- bench.node_cpu --agents 8 --cpu-time")
    if args.rounds < 1:
        p.error("--rounds must be at least 1")
    trees = {"A": args.a_dir, "B": args.b_dir}
    for name, tree in trees.items():
        if not (tree / "bench").is_dir():
            p.error(f"--{name.lower()}-dir {tree}: not a checkout of this project")
        prepare(tree)
    values: dict[str, dict[str, list[float]]] = {"A": {}, "B": {}}
    for r in range(args.rounds):
        for name in ("A", "B") if r % 2 == 0 else ("B", "A"):
            for figure, value in figures(run(trees[name], command)).items():
                values[name].setdefault(figure, []).append(value)
            print(f"round {r + 1} {name} done", file=sys.stderr, flush=True)
    print(f"{' '.join(command)}: the least of {args.rounds} runs a tree, alternately "
          f"(A {args.a_dir}, B {args.b_dir})")
    print(f"  {'figure':<32} {'A least':>9} {'B least':>9} {'B/A':>6} {'A median':>9} "
          f"{'B median':>9} {'B/A':>6}")
    for figure in values["A"]:
        a, b = values["A"][figure], values["B"].get(figure)
        if not b:
            continue
        pairs = ((min(a), min(b)), (statistics.median(a), statistics.median(b)))
        cells = [f"{x:9.2f} {y:9.2f} " + (f"{y / x:6.3f}" if x else "     -") for x, y in pairs]
        print(f"  {figure:<32} {cells[0]} {cells[1]}   "
              f"(A {' '.join(f'{v:g}' for v in a)}; B {' '.join(f'{v:g}' for v in b)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
