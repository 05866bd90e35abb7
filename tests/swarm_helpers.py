"""Shared helpers of the swarm tests: start launch/swarm.py as a real process tree and read its
run; run launch/experiment.py and read its tables."""

import csv
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SWARM = ROOT / "launch" / "swarm.py"
EXPERIMENT = ROOT / "launch" / "experiment.py"


def experiment(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run ``launch/experiment.py`` with ``args`` to completion, its output captured."""
    return subprocess.run([sys.executable, str(EXPERIMENT), *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def read_csv(path: Path) -> list[dict]:
    """A CSV file's rows, each by its header's names."""
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def swarm_command(out: Path, *options: str) -> list[str]:
    return [sys.executable, str(SWARM), "--out", str(out), "--no-progress", *options]


def run_swarm(out: Path, *options: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """Run a swarm to completion; the whole process tree is its own session."""
    return subprocess.run(
        swarm_command(out, *options), cwd=ROOT, capture_output=True, text=True, timeout=timeout,
        start_new_session=True, env={**os.environ, "NNQL_LOG": "WARNING"},
    )


def run_swarms(runs: dict, at_once: int = 2, timeout: float = 240) -> dict:
    """:func:`run_swarm` for each ``name: (out, options)`` of ``runs``, ``at_once`` at a time
    (runs that wait on each other for nothing: on 2 cores, two single-threaded runs take about
    the time of one); returns ``name: CompletedProcess``."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=at_once) as pool:
        done = {name: pool.submit(run_swarm, out, *options, timeout=timeout)
                for name, (out, options) in runs.items()}
        return {name: future.result() for name, future in done.items()}


FAILURE_LOG_LINES = 60
"""How many of its last log lines a swarm that did not finish in time shows in the failure."""


class SwarmProcess(subprocess.Popen):
    """A launched swarm whose output goes to files (a pipe nobody reads would block its logs)."""

    def __init__(self, command: list[str], log_dir: Path) -> None:
        log_dir.mkdir(parents=True, exist_ok=True)
        self.stdout_path = log_dir / "stdout.log"
        self.stderr_path = log_dir / "stderr.log"
        with open(self.stdout_path, "w") as out, open(self.stderr_path, "w") as err:
            super().__init__(command, cwd=ROOT, stdout=out, stderr=err, text=True,
                             start_new_session=True)

    def stderr_text(self) -> str:
        return self.stderr_path.read_text()

    def finish(self, timeout: float) -> str:
        """Wait for the swarm to exit; returns its stderr. A swarm still running after
        ``timeout`` fails the test with the last lines it logged (its whole log stays in
        :attr:`stderr_path` until pytest rotates its temporary folders)."""
        try:
            self.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            tail = "\n".join(self.stderr_text().splitlines()[-FAILURE_LOG_LINES:])
            raise AssertionError(f"the swarm still ran after {timeout:g} s; the last lines of "
                                 f"{self.stderr_path}:\n{tail}") from None
        return self.stderr_text()


def start_swarm(out: Path, *options: str) -> SwarmProcess:
    """Start a swarm in its own process group (so a test can signal it like a terminal would)."""
    return SwarmProcess(swarm_command(out, *options), Path(str(out) + "-logs"))


def _live_processes():
    """(pid, process group, command line) of every live, non-zombie process."""
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").strip().decode()
        except OSError:
            continue
        if fields[0] != "Z":
            yield int(entry.name), int(fields[2]), cmdline


def group_pids(pgid: int) -> list[int]:
    """The live (non-zombie) processes of a process group."""
    return [pid for pid, group, _ in _live_processes() if group == pgid]


def find_process(title: str) -> list[int]:
    """Pids whose command line (process title) is exactly ``title``, like ``pgrep -fx``."""
    return [pid for pid, _, cmdline in _live_processes() if cmdline == title]


def stops_within(swarm: subprocess.Popen, seconds: float) -> float:
    """Wait until the swarm's whole process group is gone; returns how long that took."""
    import time

    start = time.monotonic()
    swarm.wait(timeout=10)
    while group_pids(swarm.pid) and time.monotonic() - start < seconds:
        time.sleep(0.05)
    return time.monotonic() - start


def wait_for_rows(csv_path: Path, rows: int, timeout: float, process=None) -> None:
    """Wait until ``csv_path`` holds at least ``rows`` episode rows."""
    import time

    from nnql_swarm.world.metrics import read_episodes

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if process is not None and process.poll() is not None:
            log = process.stderr_text() if hasattr(process, "stderr_text") else ""
            raise AssertionError(f"the swarm exited early ({process.returncode}): {log}")
        if csv_path.exists() and len(read_episodes(csv_path)) >= rows:
            return
        time.sleep(0.1)
    raise AssertionError(f"{csv_path} did not reach {rows} rows in {timeout} s")
