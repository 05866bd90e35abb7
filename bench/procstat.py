"""What running processes hold: resident memory, sampled from ``/proc/<pid>/status`` while they
run, and the machine's busy CPU time (``/proc/stat``)."""

import math
import os
import threading
import time
from pathlib import Path


def resident_mib(pid: int) -> float | None:
    """``VmRSS`` of a process in MiB, or None once it has gone."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return None
    for line in text.splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return None


_TICKS_PER_S = os.sysconf("SC_CLK_TCK")


def machine_busy_s() -> float:
    """CPU seconds every core of the machine has spent busy since boot (user, nice, system, irq,
    softirq and steal time: all but idle and I/O wait), in steps of ``1 / SC_CLK_TCK``."""
    fields = Path("/proc/stat").read_text().split("\n", 1)[0].split()[1:9]
    user, nice, system, _idle, _iowait, irq, softirq, steal = map(int, fields)
    return (user + nice + system + irq + softirq + steal) / _TICKS_PER_S


class TimedTicks:
    """The ticks a loop times from :meth:`start` on: their rate, and the machine's busy CPU
    microseconds a tick (:func:`machine_busy_s`), by :meth:`measure`; :attr:`window` is when
    they ran, in seconds since the epoch (what a sampler of the whole machine keeps of them)."""

    def __init__(self) -> None:
        self.wall = self.busy = 0.0
        self.window = (math.nan, math.nan)

    def start(self) -> None:
        self.wall, self.busy = time.perf_counter(), machine_busy_s()
        self.window = (time.time(), math.nan)

    def measure(self, ticks: int) -> tuple[float, float]:
        """(ticks a second, busy CPU microseconds a tick) over ``ticks`` ticks since start."""
        self.window = (self.window[0], time.time())
        return (ticks / (time.perf_counter() - self.wall),
                1e6 * (machine_busy_s() - self.busy) / ticks)


class MemorySampler:
    """Samples the resident memory of named processes every ``every_s`` seconds in a thread;
    :meth:`peaks` gives each one's largest sample (the run's middle, not its start or end)."""

    def __init__(self, every_s: float = 0.5) -> None:
        self.every_s = every_s
        self.pids: dict[str, int] = {}
        self.samples: dict[str, float] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def watch(self, name: str, pid: int) -> None:
        self.pids[name] = pid

    def __enter__(self) -> "MemorySampler":
        self._thread.start()
        return self

    def __exit__(self, *_) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        while not self._stop.wait(self.every_s):
            for name, pid in list(self.pids.items()):
                rss = resident_mib(pid)
                if rss is not None:
                    self.samples[name] = max(rss, self.samples.get(name, 0.0))

    def peaks(self) -> dict[str, float]:
        return dict(self.samples)
