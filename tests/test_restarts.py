"""Supervised restarts on record (``sim.restarts``): the supervisor names every child it
restarted and how it had exited, with real spawned processes; the run's stats add each launch's
restarts to the last's, and the launcher's last line says the run is no longer its seed's. The
distributed run with an agent killed: ``tests/test_faults.py``."""

import json
import multiprocessing as mp
import signal
import sys
import time
from pathlib import Path

import pytest

from nnql_swarm.launch.swarm import EarlyInterrupt
from nnql_swarm.transport.runfiles import stats_path
from nnql_swarm.sim import restarts
from nnql_swarm.sim.supervisor import Supervisor


def dies_once(folder: str, restarted: bool) -> None:
    if not restarted:
        sys.exit(1)
    (Path(folder) / "again").write_text("")


def waits_for_the_restart(folder: str) -> None:
    for _ in range(1200):  # 60 s
        if (Path(folder) / "again").exists():
            return
        time.sleep(0.05)
    sys.exit(1)


def test_the_supervisor_names_the_children_it_restarted(tmp_path):
    supervisor = Supervisor(mp.get_context("spawn"))
    leader = supervisor.add("leader", waits_for_the_restart, lambda _: (str(tmp_path),),
                            restartable=False)
    supervisor.add("nnql-agent-0", dies_once, lambda again: (str(tmp_path), again),
                   restartable=True)
    supervisor.add("nnql-agent-1", waits_for_the_restart, lambda _: (str(tmp_path),),
                   restartable=True)
    assert supervisor.run(leader) == 0
    assert supervisor.restarted() == {"nnql-agent-0": ["exit code 1"]}


def test_a_ctrl_c_swallowed_before_the_supervisor_took_over_stops_the_run(tmp_path):
    """The launcher's first SIGINT handler raises KeyboardInterrupt wherever it lands; where that
    is swallowed (importlib, a finalizer), the supervisor finds the handler's note and stops the
    run before it starts anyone, with the exit code of a Ctrl-C."""
    early = EarlyInterrupt()
    with pytest.raises(KeyboardInterrupt):
        early(signal.SIGINT, None)
    assert early.heard
    previous = signal.signal(signal.SIGINT, early)
    try:
        supervisor = Supervisor(mp.get_context("spawn"))
        leader = supervisor.add("leader", waits_for_the_restart, lambda _: (str(tmp_path),),
                                restartable=False)
        started = time.monotonic()
        assert supervisor.run(leader) == 130
        assert time.monotonic() - started < 5 and leader.process is None
        assert signal.getsignal(signal.SIGINT) is early, "the handler it found is put back"
        signal.signal(signal.SIGINT, EarlyInterrupt())
        supervisor = Supervisor(mp.get_context("spawn"))
        leader = supervisor.add("leader", dies_once, lambda _: (str(tmp_path), True),
                                restartable=False)
        assert supervisor.run(leader) == 0, "one that heard nothing: the run is played"
    finally:
        signal.signal(signal.SIGINT, previous)


def test_the_runs_stats_keep_every_launchs_restarts(tmp_path):
    assert restarts.of_run(tmp_path) == {}
    assert restarts.finished(tmp_path) == f"run finished: {tmp_path}"
    assert restarts.warning({}) is None
    assert restarts.record(tmp_path, {}) == {}
    assert not stats_path(tmp_path, restarts.STATS_NAME).exists()  # none: no file
    restarts.record(tmp_path, {"nnql-agent-3": ["killed by SIGKILL"]})
    both = restarts.record(tmp_path, {"nnql-agent-3": ["exit code 1"],
                                      "nnql-agent-0": ["killed by SIGKILL"]})  # a --resume's
    assert both == {"nnql-agent-0": ["killed by SIGKILL"],
                    "nnql-agent-3": ["killed by SIGKILL", "exit code 1"]}
    saved = json.loads(stats_path(tmp_path, restarts.STATS_NAME).read_text())
    assert saved == {"restarts": both} and restarts.of_run(tmp_path) == both
    assert "not the run its seed gives" in restarts.finished(tmp_path)
    line = restarts.warning(both)
    assert line is not None and "\n" not in line
    assert "nnql-agent-3 2 times (exit code 1)" in line and "no longer the run its seed" in line
