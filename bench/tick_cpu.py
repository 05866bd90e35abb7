#!/usr/bin/env python3
"""CPU time a tick costs each process of the distributed swarm: the world and every agent.

Runs ``launch/swarm.py`` (embedded Zenoh, recording off) with the options given after ``--``,
and reads each process's user + system time from ``/proc/<pid>/stat`` at two episode ends
(after ``--warm-up`` episodes, start-up excluded, and ``--episodes`` episodes later). Prints
microseconds of CPU per tick by process, their sum, and that sum as a share of what the machine's
cores offer in a tick: near 1, the tick waits for CPU, not for messages. Then, from the
processes' stats once they have stopped (``handler_cpu``: every input the node fed its machine,
``transport.adapter``), what each kind of input cost a call there, on the processes' own
caches, in the machine and in carrying out its effects (for the agents, the median agent's),
over the inputs timed in the whole run (one in eight): to set beside ``bench/node_cpu.py``'s figures, hot in one thread.

    python -m bench.tick_cpu --episodes 25 -- --preset shield-nnql --agents 8
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
from nnql_swarm.world.metrics import read_episodes

HZ = os.sysconf("SC_CLK_TCK")


def descendants(pid: int) -> list[int]:
    children = Path(f"/proc/{pid}/task/{pid}/children")
    try:
        kids = [int(k) for k in children.read_text().split()]
    except OSError:
        return []
    return [k for kid in kids for k in (kid, *descendants(kid))]


def process_cpu(pid: int) -> tuple[str, float] | None:
    """(name, user + system seconds) of a live process; None once it has gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0].decode()
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[1].split()
    name = title.rsplit(" ", 1)[0] if title.startswith("nnql-") else title  # drop the run id
    return name, (int(fields[11]) + int(fields[12])) / HZ


def episode_ends(path: Path) -> list[int]:
    """The end tick of every episode written so far (none before the file exists)."""
    try:
        return [int(row["end_tick"]) for row in read_episodes(path)]
    except (OSError, KeyError, ValueError):  # not there yet, or a row half written
        return []


def wait_rows(path: Path, rows: int, swarm: subprocess.Popen) -> int:
    """The end tick of episode ``rows - 1``, once it is written."""
    while True:
        ends = episode_ends(path)
        if len(ends) >= rows:
            return ends[rows - 1]
        if swarm.poll() is not None:
            raise SystemExit(f"the swarm exited ({swarm.returncode}) before {rows} episodes")
        time.sleep(0.02)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--warm-up", type=int, default=3, help="episodes before the first reading")
    p.add_argument("--episodes", type=int, default=25, help="episodes between the readings")
    p.add_argument("swarm_options", nargs="*", help="options of launch/swarm.py (after --)")
    args = p.parse_args()
    if args.warm_up < 1 or args.episodes < 1:
        p.error("--warm-up and --episodes must be at least 1")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        rows = out / "episodes.csv"
        command = [sys.executable, str(ROOT / "launch" / "swarm.py"), *args.swarm_options,
                   "--episodes", str(args.warm_up + args.episodes + 2), "--no-record",
                   "--no-progress", "--out", str(out)]
        # This tree's package, not the one the editable install maps (to time a tree beside
        # another, run this module from each in turn).
        path = os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH"))))
        swarm = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.DEVNULL,
                                 env={**os.environ, "PYTHONPATH": path})
        try:
            first = wait_rows(rows, args.warm_up, swarm)
            before = {pid: process_cpu(pid) for pid in descendants(swarm.pid)}
            started = time.monotonic()
            last = wait_rows(rows, args.warm_up + args.episodes, swarm)
            after = {pid: process_cpu(pid) for pid in descendants(swarm.pid)}
            seconds = time.monotonic() - started
        finally:
            swarm.terminate()
            swarm.wait()
        handlers = handler_costs(out / "stats")
    ticks = last - first
    costs = sorted(((b[0], 1e6 * (b[1] - before[pid][1]) / ticks) for pid, b in after.items()
                    if b is not None and before.get(pid) is not None), key=lambda c: -c[1])
    total = sum(us for _, us in costs)
    cores = os.cpu_count() or 1
    tick_us = 1e6 * seconds / ticks
    print(f"{ticks} ticks, {ticks / seconds:.0f} ticks/s; CPU microseconds a tick:")
    for name, us in costs:
        if us >= 1:
            print(f"  {name:<28} {us:7.0f}")
    print(f"  {'all processes':<28} {total:7.0f}  ({total / (cores * tick_us):.2f} of {cores} "
          f"cores' {cores * tick_us:.0f})")
    print("CPU microseconds a call of each input, in its process, over the whole run "
          "(the agents: the median agent's):")
    print(f"  {'input':<28} {'calls':>9} {'machine':>8} {'effects':>8}")
    for (role, name), (calls, machine, effects) in sorted(handlers.items()):
        print(f"  {role + ' ' + name:<28} {calls:9.0f} {machine:8.1f} {effects:8.1f}")
    return 0


def handler_costs(stats_dir: Path) -> dict[tuple[str, str], tuple[float, float, float]]:
    """``(role, input) -> (calls, machine us, effects us)`` from the processes' stats files: the
    world's, and the median over the agents that fed that input (and timed it: one input in
    ``transport.adapter.CPU_SAMPLE_EVERY`` is)."""
    per: dict[tuple[str, str], list[dict]] = {}
    for path in sorted(stats_dir.glob("*.json")):
        role = "world" if path.stem == "world" else "agent" if path.stem.startswith("agent-") \
            else None
        if role is None:
            continue
        for name, cost in json.loads(path.read_text()).get("handler_cpu", {}).items():
            per.setdefault((role, name), []).append(cost)
    return {key: tuple(median_of(c[field] for c in costs)
                       for field in ("calls", "machine_us", "effects_us"))
            for key, costs in per.items()}


def median_of(values) -> float:
    """The median of the values given (None: an input too rare to be timed), NaN if none is."""
    known = [v for v in values if v is not None]
    return statistics.median(known) if known else float("nan")


if __name__ == "__main__":
    sys.exit(main())
