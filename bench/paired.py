#!/usr/bin/env python3
"""Paired A/B runs of ``bench/swarm_ticks.py``: two versions (source trees) or two settings
(environment variables), run alternately, compared by the median of each pair's ratio.

A shared machine's speed drifts within minutes, so only runs made together compare; a
pair is A then B (then B then A at the next pair, so that neither always goes first), and the
ratio of each pair's figures cancels most of the drift.

    python -m bench.paired --pairs 3 --a-dir /tmp/before --b-dir . \\
        -- --agents 8 --repeats 5 --episodes 10
    python -m bench.paired --pairs 3 --a-env NNQL_ZENOH_CALLBACKS=direct \\
        --b-env NNQL_ZENOH_CALLBACKS=kept -- --agents 8 --repeats 5 --episodes 10

Everything after ``--`` goes to ``swarm_ticks.py``. Both sides run with this Python. The
editable install maps ``nnql_swarm`` to the checkout it was made from, whichever tree a side runs
in; so each side's tree is first built (``pip install --no-deps --target``, as a wheel installs
it) into a directory of its own, and runs as ``python -m bench.swarm_ticks`` in its tree with
``PYTHONPATH`` on that directory, which Python searches before the installed packages.
"""

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LINE = re.compile(r"^\s*(\d+)\s+(distributed|bare|in-process)\s+(\d+)\s")


def package_path(directory: Path, under: Path) -> Path:
    """A directory under ``under`` holding ``directory``'s package as a wheel installs it."""
    target = Path(tempfile.mkdtemp(dir=under))
    done = subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "--quiet",
                           "--target", str(target), str(directory)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"paired.py: cannot build {directory}: "
                         f"{done.stderr.strip().splitlines()[-1:]}")
    return target


def run_side(directory: Path, env: dict[str, str], args: list[str],
             path: Path) -> dict[str, float]:
    """One ``swarm_ticks.py`` run of ``directory``'s code (importable from ``path``); its median
    ticks/s by mode (a failed run is said and tried once more)."""
    python_path = os.pathsep.join(filter(None, [str(path), os.environ.get("PYTHONPATH")]))
    for attempt in (1, 2):
        done = subprocess.run([sys.executable, "-m", "bench.swarm_ticks", *args],
                              capture_output=True, text=True, cwd=directory, env={**os.environ, **env, "PYTHONPATH": python_path})
        if done.returncode == 0:
            break
        print(f"  swarm_ticks.py failed ({done.returncode}), attempt {attempt}: "
              f"{done.stderr.strip().splitlines()[-1:]}", flush=True)
    else:
        raise SystemExit(f"swarm_ticks.py failed twice in {directory}")
    rates = {}
    for line in done.stdout.splitlines():
        match = LINE.match(line)
        if match:
            rates[match.group(2)] = float(match.group(3))
    return rates


def parse_env(pairs: list[str]) -> dict[str, str]:
    out = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise SystemExit(f"paired.py: error: expected NAME=VALUE, not {pair!r}")
        out[key] = value
    return out


def main() -> int:
    argv = sys.argv[1:]
    rest = argv[argv.index("--") + 1:] if "--" in argv else []
    argv = argv[:argv.index("--")] if "--" in argv else argv
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--pairs", type=int, default=3)
    p.add_argument("--a-dir", type=Path, default=ROOT)
    p.add_argument("--b-dir", type=Path, default=ROOT)
    p.add_argument("--a-env", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--b-env", action="append", default=[], metavar="NAME=VALUE")
    args = p.parse_args(argv)
    sides = {"A": (args.a_dir.resolve(), parse_env(args.a_env)),
             "B": (args.b_dir.resolve(), parse_env(args.b_env))}
    print(f"A: {sides['A'][0]} {sides['A'][1]}\nB: {sides['B'][0]} {sides['B'][1]}\n"
          f"swarm_ticks.py {' '.join(rest)}", flush=True)
    results: dict[str, list[dict[str, float]]] = {"A": [], "B": []}
    with tempfile.TemporaryDirectory() as tmp:
        paths = {side: package_path(directory, Path(tmp)) for side, (directory, _) in sides.items()}
        for pair in range(args.pairs):
            for side in ("A", "B") if pair % 2 == 0 else ("B", "A"):
                rates = run_side(*sides[side], rest, paths[side])
                results[side].append(rates)
                print(f"pair {pair + 1} {side}: "
                      + ", ".join(f"{m} {r:.0f}" for m, r in rates.items()), flush=True)
    for mode in ("distributed", "bare"):
        a = [r[mode] for r in results["A"]]
        b = [r[mode] for r in results["B"]]
        ratios = [y / x for x, y in zip(a, b)]
        print(f"{mode}: A {statistics.median(a):.0f} ({' '.join(f'{x:.0f}' for x in a)}), "
              f"B {statistics.median(b):.0f} ({' '.join(f'{x:.0f}' for x in b)}); B/A median of "
              f"pairs {statistics.median(ratios):.3f} ({' '.join(f'{r:.2f}' for r in ratios)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
