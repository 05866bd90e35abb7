#!/usr/bin/env python3
"""Where a tick's CPU goes in the real processes, the swarm's beside the bare loop's: the Python
interpreter, numpy, the codec, our compiled kernels, Zenoh, the Linux kernel, the C library.

``perf record`` samples the whole machine while ``bench/scale.py``'s swarm (the launcher's
processes, the default preset, recording off) and then ``bench/lockstep.py``'s bare loop of as
many agents run; each sample of a receiving thread (``rx-*``: every process hands Zenoh's
runtimes to one, which receives, runs every handler and sends, docs/design.md) taken while the
ticks that each one's rate counts ran is put to the shared object it fell in, and the counts
become microseconds of CPU a tick. Start-up, the swarm's first episode, the bare loop's warm-up
and the processes' main threads are left out, as they are of the rates. So this counts what the
hot benchmarks of one thread cannot: our code and Zenoh's as they run in the swarm, on caches
the other processes cooled, with the kernel's share of every message.

    python -m bench.cpu_split --agents 8,64 --repeats 3

Needs ``perf`` (Debian: ``apt-get install linux-perf``) and the right to sample every CPU (root,
or ``kernel.perf_event_paranoid`` at most 0).
"""

import argparse
import collections
import math
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench.harness import add_preset_option, agent_sizes

FREQUENCY = 1999  # samples a second a CPU: odd, so as not to beat with a periodic tick
THREAD = re.compile(r"rx-\d+$")  # Zenoh's receiving threads, where every handler runs
SAMPLE = re.compile(  # a line of ``perf script -F comm,time,ip,dso``
    r"^\s*(?P<comm>.+?)\s+(?P<time>\d+\.\d+):\s+[0-9a-f]+\s+\((?P<dso>.*)\)\s*$")
PARTS = (  # (name, what a shared object's path contains), the first that matches
    ("Python interpreter", ("libpython", "/bin/python")),
    ("numpy", ("numpy", "openblas")),
    ("msgspec (the codec)", ("msgspec",)),
    ("our compiled kernels", ("nnql_ahead",)),
    ("Zenoh", ("zenoh",)),
    ("Linux kernel", ("kernel.kallsyms", "[vdso]")),
    ("C library", ("libc.so", "libm.so", "ld-linux")),
)
OTHER = "other"
ALL = "in all"


def part_of(dso: str) -> str:
    """The part a sample's shared object belongs to (:data:`PARTS`), else :data:`OTHER`."""
    for name, marks in PARTS:
        if any(mark in dso for mark in marks):
            return name
    return OTHER


def receiving_samples(script: str, window: tuple[float, float]) -> collections.Counter:
    """Samples of the receiving threads taken within ``window`` (seconds since the epoch), by
    part, from the text of ``perf script -F comm,time,ip,dso`` over a realtime-clocked record."""
    began, ended = window
    counts: collections.Counter = collections.Counter()
    for line in script.splitlines():
        match = SAMPLE.match(line)
        if (match and THREAD.match(match["comm"].strip())
                and began <= float(match["time"]) <= ended):
            counts[part_of(match["dso"])] += 1
    return counts


class MachineSamples:
    """``perf record`` over every CPU while the ``with`` block runs, its samples stamped by the
    realtime clock (as ``time.time()``); :meth:`by_part` reads it."""

    def __init__(self, directory: Path) -> None:
        self.data = directory / "perf.data"
        self._perf: subprocess.Popen | None = None

    def __enter__(self) -> "MachineSamples":
        self._perf = subprocess.Popen(
            ["perf", "record", "-a", "-q", "-k", "realtime", "-F", str(FREQUENCY),
             "-o", str(self.data)],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        time.sleep(1.0)  # perf opens its buffers on every CPU before the run starts
        if self._perf.poll() is not None:
            raise SystemExit(f"perf record failed: {self._perf.stderr.read().strip()}")
        return self

    def __exit__(self, *exc) -> None:
        assert self._perf is not None
        self._perf.send_signal(signal.SIGINT)
        _, errors = self._perf.communicate(timeout=60)
        if self._perf.returncode not in (0, -signal.SIGINT) or not self.data.exists():
            raise SystemExit(f"perf record failed: {errors.strip()}")

    def by_part(self, window: tuple[float, float]) -> collections.Counter:
        """The receiving threads' samples within ``window`` by part (:func:`receiving_samples`)."""
        done = subprocess.run(["perf", "script", "-i", str(self.data), "-F", "comm,time,ip,dso"],
                              capture_output=True, text=True)
        if done.returncode != 0:
            raise SystemExit(f"perf script failed: {done.stderr.strip()}")
        return receiving_samples(done.stdout, window)


def per_tick_us(counts: collections.Counter, ticks: int) -> dict[str, float]:
    """Samples by part as microseconds of CPU a tick."""
    return {part: 1e6 * count / FREQUENCY / ticks for part, count in counts.items()}


def median_of(splits: list[dict[str, float]], part: str) -> float:
    """The median over runs of one part's microseconds a tick (:data:`ALL`: of every part's)."""
    return statistics.median(sum(split.values()) if part == ALL else split.get(part, 0.0)
                             for split in splits)


def sampled(run, directory: Path) -> tuple[dict, dict[str, float]]:
    """``run()``'s result and its receiving threads' CPU a tick by part, over the ticks its
    rate counts (the result's ``measured_ticks``, which ran within its ``window``)."""
    with MachineSamples(directory) as samples:
        result = run()
    if any(math.isnan(t) for t in result["window"]):
        raise SystemExit("the run did not finish its ticks: nothing to split")
    return result, per_tick_us(samples.by_part(result["window"]), result["measured_ticks"])


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=lambda text: agent_sizes(p, text), default=[8, 64],
                   help="comma-separated agent counts (default: 8,64)")
    p.add_argument("--repeats", type=int, default=3, help="runs of each, medians (default: 3)")
    p.add_argument("--episodes", type=int, default=6, help="the swarm's episodes (default: 6)")
    p.add_argument("--bare-ticks", type=int, default=2000, help="ticks of each bare loop")
    p.add_argument("--bare-work", type=int, default=0, metavar="OBJECTS",
                   help="objects of Python each bare agent reads before it answers "
                        "(bench.lockstep's --python-work; default 0)")
    add_preset_option(p)
    args = p.parse_args()
    if shutil.which("perf") is None:
        p.error("perf is not installed (Debian: apt-get install linux-perf)")
    if args.repeats < 1 or args.episodes < 2 or args.bare_ticks < 10 or args.bare_work < 0:
        p.error("--repeats at least 1, --episodes at least 2 (the first is not timed), "
                "--bare-ticks at least 10, --bare-work at least 0")

    from bench import lockstep
    from bench.scale import swarm_once
    from nnql_swarm.transport.topology import embedded_topology

    for n in args.agents:
        topology = embedded_topology(n)
        swarm: list[dict[str, float]] = []
        bare: list[dict[str, float]] = []
        rates: dict[str, list[float]] = {"swarm": [], "bare": []}
        for repeat in range(args.repeats):
            with tempfile.TemporaryDirectory() as tmp:
                result, split = sampled(lambda: swarm_once(
                    n, args.preset, args.episodes, 100, 0, topology), Path(tmp))
                swarm.append(split)
                rates["swarm"].append(result["rate"])
            with tempfile.TemporaryDirectory() as tmp:
                result, split = sampled(lambda: lockstep.run(
                    n, topology, args.bare_ticks, args.bare_work), Path(tmp))
                bare.append(split)
                rates["bare"].append(result["rate"])
            print(f"  {n} agents, repeat {repeat + 1}: swarm {sum(swarm[-1].values()):.0f} us "
                  f"a tick ({rates['swarm'][-1]:.0f} ticks/s), bare {sum(bare[-1].values()):.0f} "
                  f"us ({rates['bare'][-1]:.0f} ticks/s)", file=sys.stderr, flush=True)
        print(f"\n{n} agents ({topology}, preset {args.preset}): the receiving threads' CPU, "
              f"us a tick, medians of {args.repeats} (swarm {statistics.median(rates['swarm']):.0f}"
              f" ticks/s, bare loop {statistics.median(rates['bare']):.0f}"
              + (f", its agents reading {args.bare_work} objects a tick" if args.bare_work else "")
              + ")")
        print("| part | swarm | bare loop | the swarm's more |")
        print("| --- | ---: | ---: | ---: |")
        for part in [name for name, _ in PARTS] + [OTHER, ALL]:
            s, b = median_of(swarm, part), median_of(bare, part)
            print(f"| {part} | {s:.0f} | {b:.0f} | {s - b:.0f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
