"""Faults with real processes: agents killed, stalled and restarted; the world killed and resumed.

Every test checks what the issue promises: the run completes, every episode is recorded exactly
once, no tick waits longer than the deadline, and no learned value is lost.
"""

import atexit
import json
import os
import re
import shutil
import signal
import subprocess
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from nnql_swarm.transport.runlock import RunLock
from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.world import world_checkpoint
from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.transport.ports import free_port
from tests.swarm_helpers import (
    ROOT, SwarmProcess, find_process, group_pids, run_swarm, start_swarm, stops_within,
    swarm_command, wait_for_rows,
)
from nnql_swarm.world.metrics import read_episodes

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

DEADLINE_S = 0.5


def episodes_once(out, n: int) -> list[dict]:
    rows = read_episodes(out / "episodes.csv")
    assert [int(r["episode"]) for r in rows] == list(range(n))
    return rows


def stats(out, name: str) -> dict:
    return json.loads((out / "stats" / f"{name}.json").read_text())


def test_processes_are_named_for_ps_and_pgrep(tmp_path):
    swarm = start_swarm(tmp_path / "named", "--agents", "3", "--episodes", "400", "--max-steps", "30",
                        "--run-id", "named", "--no-record")
    try:
        wait_for_rows(tmp_path / "named" / "episodes.csv", 1, 90, swarm)
        assert len(find_process("nnql-world named")) == 1
        for agent in range(3):
            assert len(find_process(f"nnql-agent {agent} named")) == 1
        found = subprocess.run(["pgrep", "-f", "nnql-agent 1 named"], capture_output=True, text=True)
        assert found.stdout.split() == [str(p) for p in find_process("nnql-agent 1 named")]
    finally:
        os.killpg(swarm.pid, signal.SIGINT)
        swarm.wait(timeout=10)


def test_a_killed_agent_is_restarted_from_its_checkpoint(tmp_path):
    out = tmp_path / "killed"
    swarm = start_swarm(out, "--agents", "8", "--episodes", "30", "--max-steps", "40",
                        "--run-id", "killed", "--deadline", str(DEADLINE_S), "--no-record")
    try:
        wait_for_rows(out / "episodes.csv", 3, 120, swarm)
        [victim] = find_process("nnql-agent 3 killed")
        os.kill(victim, signal.SIGKILL)
        saved = out / "agent-3-at-kill.ckpt"
        shutil.copy(out / "checkpoints" / "agent-3.ckpt", saved)
        stderr = swarm.finish(timeout=240)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 0, stderr
    assert "nnql-agent-3 exited (killed by SIGKILL)" in stderr
    assert stats(out, "supervisor") == {"restarts": {"nnql-agent-3": ["killed by SIGKILL"]}}
    last = stderr.strip().splitlines()[-1]
    assert last.startswith(f"run finished: {out}; not the run its seed gives"), stderr
    assert "the run is no longer the run its seed gives" in stderr
    rows = episodes_once(out, 30)
    config = SwarmConfig.from_json((out / "config.json").read_text())
    at_kill = AgentBrain(3, config)
    agent_checkpoint.load(saved, at_kill)
    assert np.abs(at_kill.learner.q_ca).sum() > 0, "the checkpoint held learned values"
    resumed = stats(out, "agent-3")["resumed"]
    assert resumed is not None, "the restarted agent loaded a checkpoint"
    assert resumed["fingerprint"] == agent_checkpoint.fingerprint(at_kill), "and it was the one at the kill"
    assert sum(int(r["missed_intents"]) for r in rows) > 0, "the dead agent's ticks were missed"
    assert stats(out, "world")["violations"] == 0
    assert_copies_equal_the_worlds(out, config, range(8))


def assert_copies_equal_the_worlds(out, config, agents) -> None:
    """Every agent's last checkpoint holds the world's shared table of the same episode: a
    restarted agent, or a restarted world, was sent the whole table and caught up."""
    shared = world_checkpoint.load(world_checkpoint.table_path(out), config, config.episodes - 1)
    for agent in agents:
        mine = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), ())
        assert np.array_equal(mine["q_ds"], shared[0]), agent
        assert np.array_equal(mine["q_ca"], shared[1]), agent


@pytest.mark.serial  # a tick within 250 ms of the deadline
def test_a_stalled_agent_costs_at_most_the_deadline_and_its_stale_intents_are_rejected(tmp_path):
    out = tmp_path / "stalled"
    swarm = start_swarm(out, "--agents", "8", "--episodes", "30", "--max-steps", "40",
                        "--run-id", "stalled", "--deadline", str(DEADLINE_S), "--no-record")
    try:
        wait_for_rows(out / "episodes.csv", 2, 120, swarm)
        [victim] = find_process("nnql-agent 5 stalled")
        os.kill(victim, signal.SIGSTOP)
        time.sleep(3.0)
        os.kill(victim, signal.SIGCONT)
        stderr = swarm.finish(timeout=240)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 0, stderr
    rows = episodes_once(out, 30)
    slowest = max(float(r["max_tick_ms"]) for r in rows)
    assert slowest <= DEADLINE_S * 1000 + 250, f"a tick took {slowest} ms"
    assert slowest >= DEADLINE_S * 1000, "the stall did make the world wait for the deadline"
    assert sum(int(r["missed_intents"]) for r in rows) >= 3
    world = stats(out, "world")
    assert world["rejected"].get("stale-tick", 0) >= 1
    assert world["violations"] == 0
    assert world["late_ticks"] >= 1
    assert re.search(r"closed at its [\d.]+ s deadline without the intents of live agents "
                     r"\[([\d, ]*, )?5(, [\d, ]*)?\]", stderr), "the world names the stalled agent"
    assert find_process("nnql-agent 5 stalled") == []


def test_a_killed_world_resumes_without_duplicate_or_missing_episodes(tmp_path):
    out = tmp_path / "resumed"
    options = ("--agents", "8", "--episodes", "20", "--max-steps", "30", "--run-id", "resumed")
    swarm = start_swarm(out, *options)
    try:
        wait_for_rows(out / "episodes.csv", 3, 120, swarm)
        [world] = find_process("nnql-world resumed")
        os.kill(world, signal.SIGKILL)
        stderr = swarm.finish(timeout=30)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode != 0
    assert "--resume" in stderr
    done = len(read_episodes(out / "episodes.csv"))
    assert done < 20
    resumed = run_swarm(out, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert f"resuming resumed at episode {done}" in resumed.stderr
    rows = episodes_once(out, 20)
    ticks = [int(r["end_tick"]) for r in rows]
    assert ticks == sorted(ticks) and len(set(ticks)) == 20
    again = run_swarm(out, "--resume")
    assert again.returncode == 0 and "already complete" in again.stderr


@pytest.mark.serial  # within 3 s
def test_sigterm_to_the_launcher_stops_everything_within_3_s(tmp_path):
    out = tmp_path / "terminated"
    swarm = start_swarm(out, "--agents", "8", "--episodes", "1000", "--run-id", "terminated")
    try:
        wait_for_rows(out / "episodes.csv", 2, 120, swarm)
        swarm.send_signal(signal.SIGTERM)  # the launcher alone, as a service manager would
        assert stops_within(swarm, 3) < 3
        assert group_pids(swarm.pid) == []
        assert swarm.returncode == 130
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    config = SwarmConfig.from_json((out / "config.json").read_text())
    for agent in range(8):
        agent_checkpoint.load(out / "checkpoints" / f"agent-{agent}.ckpt", AgentBrain(agent, config))
    episodes_once(out, len(read_episodes(out / "episodes.csv")))


def test_agents_reconnect_to_a_restarted_world(tmp_path):
    out = tmp_path / "reconnect"
    port = free_port()
    common = ("--agents", "6", "--episodes", "80", "--max-steps", "30", "--run-id", "reconnect")
    agents = SwarmProcess(
        swarm_command(out, *common, "--role", "agents", "--connect", f"tcp/127.0.0.1:{port}",
                      "--listen", "tcp/127.0.0.1:0"), tmp_path / "agents-logs")
    world_command = swarm_command(out, *common, "--role", "world", "--no-record",
                                  "--listen", f"tcp/127.0.0.1:{port}")
    world = SwarmProcess(world_command, tmp_path / "world-logs")
    try:
        wait_for_rows(out / "episodes.csv", 3, 120, world)
        [world_pid] = find_process("nnql-world reconnect")
        os.kill(world_pid, signal.SIGKILL)
        world.wait(timeout=30)
        assert world.returncode != 0
        resumed = subprocess.run(
            [*world_command[:-2], "--resume", "--listen", f"tcp/127.0.0.1:{port}"],
            cwd=ROOT, capture_output=True, text=True, timeout=240, start_new_session=True)
        assert resumed.returncode == 0, resumed.stderr
        agents.wait(timeout=30)
        assert agents.returncode == 0, agents.stderr_text()
    finally:
        for process in (agents, world):
            if group_pids(process.pid):
                os.killpg(process.pid, signal.SIGKILL)
    episodes_once(out, 80)
    for agent in range(6):
        assert stats(out, f"agent-{agent}")["shutdown_by_world"]
    assert stats(out, "incarnation") == {"world": 2}  # the second world's messages say so
    assert stats(out, "world")["forgers"] == []  # no honest agent's intent taken as forged
    assert_copies_equal_the_worlds(out, SwarmConfig.from_json((out / "config.json").read_text()),
                                   range(6))


def test_resume_refuses_corrupt_or_foreign_checkpoints_naming_the_file(tmp_path):
    out = tmp_path / "broken"
    done = run_swarm(out, "--agents", "3", "--episodes", "4", "--max-steps", "20", "--in-process",
                     "--no-record")
    assert done.returncode == 0, done.stderr
    lines = (out / "episodes.csv").read_text().splitlines(keepends=True)
    (out / "episodes.csv").write_text("".join(lines[:3]) + lines[3][:7])  # a crash mid-row
    kept = {"agent-1.ckpt": (out / "checkpoints" / "agent-1.ckpt").read_bytes()}
    shutil.copy(out / "checkpoints" / "agent-0.ckpt", out / "checkpoints" / "agent-1.ckpt")
    foreign = run_swarm(out, "--resume", timeout=60)
    assert foreign.returncode == 2
    assert "agent-1.ckpt: belongs to agent 0" in foreign.stderr
    (out / "checkpoints" / "agent-1.ckpt").write_bytes(b"not a checkpoint")
    corrupt = run_swarm(out, "--resume", timeout=60)
    assert corrupt.returncode == 2
    assert "agent-1.ckpt: not a readable checkpoint" in corrupt.stderr
    assert len(corrupt.stderr.strip().splitlines()) == 1
    assert len(read_episodes(out / "episodes.csv")) == 2, "the half-written row was dropped"
    (out / "checkpoints" / "agent-1.ckpt").write_bytes(kept["agent-1.ckpt"])
    ahead = run_swarm(out, "--resume", timeout=60)  # every checkpoint two episodes past the rows
    assert ahead.returncode == 2
    assert "world.ckpt: holds the table after episode 3, not after episode 1" in ahead.stderr
    (out / "checkpoints" / "world.ckpt").unlink()  # the world stands before episode 0
    again = run_swarm(out, "--resume", timeout=120)
    assert again.returncode == 0, again.stderr
    assert "at episode 0 (tick 0); episodes 0..1 are played again" in again.stderr
    episodes_once(out, 4)
    nothing = run_swarm(tmp_path / "nothing-here", "--resume", timeout=60)
    assert nothing.returncode == 2 and "no run to resume here" in nothing.stderr


def test_an_unreachable_router_ends_the_run_with_one_clear_line_per_process(tmp_path):
    port = free_port()  # nobody listens there
    result = run_swarm(tmp_path / "nowhere", "--role", "agents", "--run-id", "nowhere",
                       "--agents", "2", "--mode", "client", "--connect", f"tcp/127.0.0.1:{port}",
                       timeout=60)
    assert result.returncode == 3
    assert "Traceback" not in result.stderr
    assert result.stderr.count(f"cannot open a Zenoh client (tcp/127.0.0.1:{port})") == 2
    assert "could not start" in result.stderr


def test_a_launcher_killed_outright_takes_its_processes_with_it(tmp_path):
    out = tmp_path / "orphans"
    swarm = start_swarm(out, "--agents", "4", "--episodes", "1000", "--run-id", "orphans",
                        "--no-record")
    try:
        wait_for_rows(out / "episodes.csv", 1, 120, swarm)
        children = [p for title in ["nnql-world orphans"] + [f"nnql-agent {i} orphans"
                                                            for i in range(4)]
                    for p in find_process(title)]
        assert len(children) == 5
        os.kill(swarm.pid, signal.SIGKILL)
        swarm.wait(timeout=10)

        def alive() -> list[int]:
            return [p for p in children if Path(f"/proc/{p}").exists()
                    and Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"]

        deadline = time.monotonic() + 30  # each stops as on Ctrl-C, which takes longer under load
        while alive() and time.monotonic() < deadline:
            time.sleep(0.1)
        left = alive()
        assert left == [], "processes outlived their launcher"
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    config = SwarmConfig.from_json((out / "config.json").read_text())
    for agent in range(4):  # they stopped as on Ctrl-C: checkpoints intact
        agent_checkpoint.load(out / "checkpoints" / f"agent-{agent}.ckpt", AgentBrain(agent, config))


def test_a_forged_shutdown_on_the_unsecured_layout_ends_the_run_with_a_reason(tmp_path):
    """A peer that says the world's shutdown stops every agent (nothing tells it apart without
    the secured layout); the world, left alone, ends the run with an error once none came back
    in the time it waits for them at the start (``--agent-wait``, here 20 s instead of the
    default 60, which ``tests/test_agent_machine.py`` checks), instead of ticking alone."""
    import zenoh

    from nnql_swarm.protocol import keys
    from nnql_swarm.protocol.messages import WORLD_SENDER, Control, encode
    from nnql_swarm.transport.settings import TransportSettings
    wait = 20.0
    out, port = tmp_path / "forged", free_port()
    swarm = start_swarm(out, "--agents", "2", "--episodes", "100000", "--max-steps", "20",
                        "--run-id", "forged", "--no-record", "--port", str(port),
                        "--agent-wait", f"{wait:g}")
    rogue = TransportSettings(mode="peer", listen=("tcp/127.0.0.1:0",),
                              connect=(f"tcp/127.0.0.1:{port}",))
    try:
        wait_for_rows(out / "episodes.csv", 1, 120, swarm)
        with zenoh.open(rogue.zenoh_config()) as session:
            seen: set[str] = set()
            with session.liveliness().declare_subscriber(
                    keys.alive_key_all("forged", keys.ROLE_AGENT),
                    lambda sample: seen.add(str(sample.key_expr)), history=True):
                deadline = time.monotonic() + 30
                while len(seen) < 2 and time.monotonic() < deadline:
                    time.sleep(0.05)
            shutdown = Control(run="forged", tick=1, sender=WORLD_SENDER, command="shutdown")
            forged_at = time.monotonic()
            for _ in range(3):
                session.put(keys.control_key("forged"), encode(shutdown))
                time.sleep(0.2)
        stderr = swarm.finish(timeout=wait + 60)
        took = time.monotonic() - forged_at
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 1, stderr
    assert "none came back within 20 s: the world does not play alone" in stderr, stderr
    assert "continue the run with" in stderr and "Traceback" not in stderr, stderr
    assert "--agent-wait 20" in stderr, stderr  # the command that continues it keeps the wait
    assert wait <= took < wait + 30, took
    assert all(stats(out, f"agent-{i}")["shutdown_by_world"] for i in range(2))
    assert len(read_episodes(out / "episodes.csv")) < 100000


def test_agents_whose_world_stays_away_stop_with_a_message(tmp_path):
    """An agent host that cannot see its world for longer than ``--world-wait`` (the world
    killed and not resumed; or one that completed while the host was cut off) stops, saying
    so, instead of waiting for ever; the supervisor does not restart its agents."""
    out = tmp_path / "away"
    port = free_port()
    common = ("--agents", "2", "--episodes", "100000", "--max-steps", "20", "--run-id", "away",
              "--no-record")
    agents = SwarmProcess(
        swarm_command(out, *common, "--role", "agents", "--connect", f"tcp/127.0.0.1:{port}",
                      "--listen", "tcp/127.0.0.1:0", "--world-wait", "3"),
        tmp_path / "agents-logs")
    world = SwarmProcess(swarm_command(out, *common, "--role", "world",
                                       "--listen", f"tcp/127.0.0.1:{port}"),
                         tmp_path / "world-logs")
    try:
        wait_for_rows(out / "episodes.csv", 2, 120, world)
        os.killpg(world.pid, signal.SIGKILL)
        killed_at = time.monotonic()
        world.wait(timeout=30)
        stderr = agents.finish(timeout=60)
        took = time.monotonic() - killed_at
    finally:
        for process in (agents, world):
            if group_pids(process.pid):
                os.killpg(process.pid, signal.SIGKILL)
    assert agents.returncode == 4, stderr
    assert "no world for 3 s (--world-wait)" in stderr and "Traceback" not in stderr, stderr
    assert "restarting" not in stderr, stderr
    assert 3 <= took < 30, took
    assert all(stats(out, f"agent-{i}")["world_lost"] for i in range(2))


@contextmanager
def tmpfs(disk: Path, size: str):
    """``disk`` made a tmpfs of ``size`` (``mount``'s, e.g. ``1m``) for the block; the test is
    skipped where mounting one needs a root this machine does not give."""
    disk.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(disk)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a small tmpfs here (needs root): {mounted.stderr.strip()}")
    try:
        yield disk
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


@pytest.fixture
def small_disk(tmp_path):
    with tmpfs(tmp_path / "disk", "256k") as disk:
        yield disk


def fill(disk: Path) -> None:
    with open(disk / "filler", "wb", buffering=0) as filler:
        with pytest.raises(OSError, match="No space"):
            while True:
                filler.write(bytes(4096))


def test_a_recording_the_full_disk_refuses_stops_the_world_before_its_row(small_disk, capsys):
    """The world's part of the recording on a disk that fills: the flush before an episode's
    row fails, and the world stops as for any of its files (the row unwritten, the run
    resumable), instead of recording nothing more and flushing in vain at every episode.
    Closing the stream then returns, whatever Rerun's file sink is left waiting for."""
    from nnql_swarm.recording.sinks import RecordingPlan
    from nnql_swarm.recording.world import WorldViz
    from nnql_swarm.transport.runfiles import check_space, out_of_space

    config = SwarmConfig(run_id="full", n_agents=2, episodes=2, max_steps=5)
    parts = small_disk / "parts"
    viz = WorldViz(config, RecordingPlan("full", parts_dir=parts).open("world"), files=parts)
    check_space(parts)
    fill(small_disk)
    with pytest.raises(OSError) as refused:
        check_space(parts)
    assert out_of_space(refused.value)
    assert [path.name for path in parts.iterdir()] == [f"world.{os.getpid()}.rrd"], \
        "the probe is gone"
    viz.rec.log("noise", rr_points(20_000))
    with pytest.raises(OSError) as stopped:
        viz.before_row()
    assert out_of_space(stopped.value)
    started = time.monotonic()
    viz.close()
    assert time.monotonic() - started < 10
    assert "Traceback" not in capsys.readouterr().err
    # The stream is left waiting on the full disk, in a thread that a world process's exit
    # ends: a multiprocessing child leaves by os._exit, without exit hooks. This process would
    # wait for it in Rerun's exit hook, for ever: pytest run alone did, after every test passed.
    import rerun as rr

    atexit.unregister(rr.rerun_shutdown)


def rr_points(n: int):
    import rerun as rr

    return rr.Points2D(np.random.default_rng(0).random((n, 2)))


def test_a_full_disk_stops_the_run_in_a_line_and_what_was_written_resumes(tmp_path):
    """The run's folder on a 1 MiB tmpfs: the recording, the checkpoints and the rows fill it.
    Every process says it has no space left (no traceback), the launcher stops the run with
    the command that continues it and exit code 5; with space again, that command completes
    the run, every episode once. (Whether it is the run left alone depends on where the disk
    filled: the agents' checkpoints, rewritten in place, may have gone two episodes past the
    world's last row, which the resume then says; and an agent stalled on the filling disk may
    miss the tick's deadline, after which the run is another, as any missed intent makes it.)"""
    from nnql_swarm.transport.runfiles import EXIT_NO_SPACE

    # 120 episodes record about 6 MB (the world's part alone about 50 KB an episode): the
    # 1 MiB disk fills within the first 30, and the rest, played on resume and left alone, is
    # what the test spends its time on
    options = ("--agents", "2", "--grid", "5x5", "--max-steps", "8", "--episodes", "120",
               "--seed", "6")
    with tmpfs(tmp_path / "disk", "1m") as disk:
        full = run_swarm(disk / "run", *options, timeout=240)
        assert full.returncode == EXIT_NO_SPACE, full.stderr
        assert "Traceback" not in full.stderr, full.stderr
        last = full.stderr.strip().splitlines()[-1]
        assert last.startswith(f"no space left for the run's files in {disk / 'run'}: the run "
                               f"stopped; once there is space, continue it with "), last
        assert "--resume" in last
        subprocess.run(["mount", "-o", "remount,size=512m", str(disk)], check=True)
        resumed = run_swarm(disk / "run", "--resume", timeout=240)
        assert resumed.returncode == 0, resumed.stderr
        rows = episodes_once(disk / "run", 120)
        assert (disk / "run" / "run.rrd").is_file()
    if "is not the one left alone" not in resumed.stderr:
        alone = run_swarm(tmp_path / "alone", *options, "--in-process", "--no-record")
        assert alone.returncode == 0, alone.stderr
        from nnql_swarm.world.engine import EPISODE_FIELDS

        left_alone = read_episodes(tmp_path / "alone" / "episodes.csv")
        # an intent that missed its deadline (an agent stalled on the filling disk) changes the
        # run from that episode on, as anywhere else: the rows before it are the seed's
        first_miss = next((i for i, r in enumerate(rows) if int(r["missed_intents"])), len(rows))
        assert first_miss > 0, "the run missed an intent in its first episode"
        assert [tuple(r[f] for f in EPISODE_FIELDS) for r in rows[:first_miss]] == \
            [tuple(r[f] for f in EPISODE_FIELDS) for r in left_alone[:first_miss]]


def test_a_run_lock_that_cannot_name_its_holder_on_a_full_disk_lets_the_folder_go(small_disk):
    """The lock is taken, then its file cannot be written: the error reaches the caller (a
    one-line refusal at the command line) and the lock goes with it, so that the same process
    (the API's, in a notebook) can start the run once there is room."""
    fill(small_disk)
    with pytest.raises(OSError, match="No space"):
        RunLock(small_disk)
    (small_disk / "filler").unlink()
    RunLock(small_disk).release()  # not refused: nobody holds the folder
