"""A run folder has one owner at a time (``transport.runlock``): a second run, or a second
``--resume``, into a folder a run is using is refused in one line with exit code 2, and the run
that owns it completes with every episode once; a launcher killed outright leaves the folder
free to resume."""

import os
import signal
import subprocess
import sys

import pytest

from nnql_swarm.transport.runlock import RunLock, RunLocked
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import (
    ROOT, SwarmProcess, start_swarm, stops_within, swarm_command, wait_for_rows,
)
from tests.test_cli import one_line_exit_2

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

RUN = ("--agents", "2", "--grid", "5x5", "--max-steps", "8", "--seed", "3", "--no-record")


def second(command: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=120)


def test_a_second_run_or_resume_into_a_folder_in_use_is_refused_and_the_first_loses_nothing(
        tmp_path):
    out = tmp_path / "run"
    first = start_swarm(out, *RUN, "--episodes", "2000")
    try:
        wait_for_rows(out / "episodes.csv", 1, timeout=120, process=first)
        before = (out / "config.json").read_text()
        one_line_exit_2(second(swarm_command(out, *RUN, "--episodes", "2000")),
                        f"{out} is in use by another run (process {first.pid})")
        one_line_exit_2(second(swarm_command(out, "--resume")), "is in use by another run")
        assert (out / "config.json").read_text() == before
        assert first.finish(timeout=300) and first.returncode == 0, first.stderr_text()
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
    assert [int(row["episode"]) for row in read_episodes(out / "episodes.csv")] == \
        list(range(2000))


def test_two_runs_started_together_into_one_folder_make_one_run(tmp_path):
    out = tmp_path / "run"
    both = [SwarmProcess(swarm_command(out, *RUN, "--episodes", "20"), tmp_path / f"logs-{i}")
            for i in range(2)]
    try:
        for swarm in both:
            swarm.finish(timeout=240)
    finally:
        for swarm in both:
            if swarm.poll() is None:
                os.killpg(swarm.pid, signal.SIGKILL)
    assert sorted(swarm.returncode for swarm in both) == [0, 2], [s.stderr_text() for s in both]
    refused = next(swarm for swarm in both if swarm.returncode == 2)
    lines = refused.stderr_text().strip().splitlines()
    assert len(lines) == 1 and ("in use by another run" in lines[0]
                                or "already holds a run" in lines[0]), lines
    assert [int(row["episode"]) for row in read_episodes(out / "episodes.csv")] == \
        list(range(20))


def test_a_launcher_killed_outright_leaves_its_folder_free(tmp_path):
    out = tmp_path / "run"
    first = start_swarm(out, *RUN, "--episodes", "40")
    try:
        wait_for_rows(out / "episodes.csv", 2, timeout=120, process=first)
        first.kill()  # the launcher alone, by SIGKILL: its processes follow it (PDEATHSIG)
        stops_within(first, 10)
    finally:
        if first.poll() is None:
            os.killpg(first.pid, signal.SIGKILL)
    resumed = second(swarm_command(out, "--resume"))
    assert resumed.returncode == 0, resumed.stderr
    assert [int(row["episode"]) for row in read_episodes(out / "episodes.csv")] == \
        list(range(40))


def test_the_lock_is_the_processs_until_released(tmp_path):
    with RunLock(tmp_path):
        held = subprocess.run(
            [sys.executable, "-c", "import sys; from nnql_swarm.transport.runlock import RunLock;"
                                   f"RunLock(sys.argv[1])", str(tmp_path)],
            capture_output=True, text=True, timeout=60)
        assert held.returncode == 1 and "RunLocked" in held.stderr
        assert f"process {os.getpid()}" in held.stderr
    RunLock(tmp_path).release()  # free again
    try:
        with RunLock(tmp_path):
            RunLock(tmp_path)  # a second open in this very process is another owner too
        raise AssertionError("the second lock was granted")
    except RunLocked:
        pass
