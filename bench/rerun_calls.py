#!/usr/bin/env python3
"""Resident memory that the Rerun SDK keeps per logging call, against values sent in columns.

Logs the same scalar values to a file sink three ways (one ``rr.log`` call per value, then
``send_columns`` in batches of 10 and of 100 values per call) in fresh processes, and prints how
much each process's resident set grew after a warm-up. A recorded swarm's processes grow by
what their calls leave behind (docs/performance.md, "Recording"), so this says what batching
their per-episode logging would save.

    python -m bench.rerun_calls --values 200000
"""

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

PATHS = 10
WARM_UP = 20_000


def resident_mib() -> float:
    for line in Path(f"/proc/{os.getpid()}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def measure(values: int, batch: int, path: Path) -> float:
    """Growth in MiB of this process while it logs ``values`` scalars, ``batch`` per call."""
    import numpy as np
    import rerun as rr

    stream = rr.RecordingStream("rerun-calls", recording_id="bench")
    stream.set_sinks(rr.FileSink(str(path)))
    names = [f"metrics/m{i}" for i in range(PATHS)]

    def send(first: int, count: int) -> None:
        for start in range(first, first + count // PATHS, batch):
            episodes = np.arange(start, start + batch)
            if batch == 1:
                stream.set_time("episode", sequence=start)
                for name in names:
                    stream.log(name, rr.Scalars(float(start)))
                continue
            index = [rr.TimeColumn("episode", sequence=episodes)]
            for name in names:
                stream.send_columns(name, index, rr.Scalars.columns(scalars=episodes * 1.0))

    send(0, WARM_UP)
    stream.flush()
    before = resident_mib()
    send(WARM_UP // PATHS, values)
    stream.flush()
    return resident_mib() - before


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--values", type=int, default=200_000)
    p.add_argument("--batches", default="1,10,100", help="values per call, comma-separated")
    p.add_argument("--child", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.child is not None:
        with tempfile.TemporaryDirectory() as tmp:
            print(f"{measure(args.values, args.child, Path(tmp) / 'calls.rrd'):.1f}")
        return 0
    print(f"{'values per call':>16} {'calls':>8} {'growth MiB':>11}")
    for batch in (int(b) for b in args.batches.split(",")):
        done = subprocess.run([sys.executable, __file__, "--values", str(args.values),
                               "--child", str(batch)], capture_output=True, text=True, check=True)
        print(f"{batch:>16} {args.values // batch:>8} {float(done.stdout):>11.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
