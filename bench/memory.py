#!/usr/bin/env python3
"""Resident memory of every process of a recorded swarm run, over a long run.

Starts ``launch/swarm.py`` with recording on (the default) and many episodes, samples each
process's resident set size (``VmRSS`` of ``/proc/<pid>/status``, found by the process titles
``nnql-world`` and ``nnql-agent``) every ``--every`` seconds for ``--minutes`` minutes, then stops
the run with Ctrl-C (SIGINT to its process group) and prints, per process, the size after the
warm-up, at the end, the growth, and the growth per minute.

    python -m bench.memory --minutes 20
    python -m bench.memory --minutes 2 --every 10 --preset nnql
"""

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TITLES = ("nnql-world", "nnql-agent")


def resident_mib(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def swarm_processes() -> dict[str, int]:
    """``title -> pid`` of the running swarm's processes (titles as ``ps`` shows them)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            title = (entry / "cmdline").read_bytes().split(b"\0")[0].decode(errors="replace")
        except OSError:
            continue
        if title.startswith(TITLES):
            found[" ".join(title.split()[:2]) if "agent" in title else "nnql-world"] = int(entry.name)
    return found


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=20.0)
    p.add_argument("--every", type=float, default=30.0, help="seconds between samples")
    p.add_argument("--warm-up", type=float, default=60.0, help="seconds before the first sample")
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--preset", default=None, help="learning preset (default: the swarm's)")
    p.add_argument("--no-record", action="store_true", help="recording off (our own memory)")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, str(ROOT / "launch" / "swarm.py"), "--agents",
                   str(args.agents), "--episodes", "1000000", "--out", str(Path(tmp) / "run"),
                   "--no-progress", *(["--preset", args.preset] if args.preset else []),
                   *(["--no-record"] if args.no_record else [])]
        swarm = subprocess.Popen(command, cwd=ROOT, start_new_session=True,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        samples: dict[str, list[tuple[float, float]]] = {}
        try:
            time.sleep(args.warm_up)
            start = time.monotonic()
            while time.monotonic() - start < args.minutes * 60:
                now = (time.monotonic() - start) / 60
                for title, pid in swarm_processes().items():
                    rss = resident_mib(pid)
                    if rss is not None:
                        samples.setdefault(title, []).append((now, rss))
                if swarm.poll() is not None:
                    print(f"the swarm ended early: {swarm.stderr.read().decode()[-2000:]}")
                    return 1
                time.sleep(args.every)
        finally:
            rows = read_rows(Path(tmp) / "run" / "episodes.csv")
            if swarm.poll() is None:
                os.killpg(swarm.pid, signal.SIGINT)
                try:
                    swarm.wait(timeout=600)  # merging a long recording takes a while
                except subprocess.TimeoutExpired:
                    os.killpg(swarm.pid, signal.SIGKILL)
    print(f"{args.minutes:g} minutes after a {args.warm_up:g} s warm-up, {len(rows)} episodes, "
          f"{sum(int(r['steps']) + 1 for r in rows)} ticks, recording "
          f"{'off' if args.no_record else 'on'}")
    print(f"{'process':<16} {'start MiB':>9} {'half MiB':>9} {'end MiB':>8} {'MiB/min':>8} "
          f"{'2nd half':>8}")
    growths = []
    for title in sorted(samples):
        series = samples[title]
        (t0, first), (th, half), (t1, last) = series[0], series[len(series) // 2], series[-1]
        rate, late = (last - first) / max(t1 - t0, 1e-9), (last - half) / max(t1 - th, 1e-9)
        growths.append(late)
        print(f"{title:<16} {first:>9.1f} {half:>9.1f} {last:>8.1f} {rate:>8.2f} {late:>8.2f}")
    print(f"median growth over the second half {statistics.median(growths):.2f} MiB/min")
    return 0


def read_rows(path: Path) -> list[dict]:
    import csv

    if not path.exists():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


if __name__ == "__main__":
    sys.exit(main())
