"""``launch/view.py`` (``nnql-view``): a saved run opens in the native viewer where there is a
display, and is served to the web viewer, with its URL, where there is none."""

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

from bench.tick_cpu import descendants, process_cpu
from nnql_swarm.launch import view
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.sinks import APP_ID
from nnql_swarm.recording.viewers import RecordingError, _recording_ids
from tests.swarm_helpers import ROOT, run_swarm

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

VIEW = ROOT / "launch" / "view.py"


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def headless() -> dict:
    return {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("view") / "run"
    done = run_swarm(out, "--agents", "2", "--episodes", "1", "--max-steps", "10", "--grid", "5x5")
    assert done.returncode == 0, done.stderr
    return out


def test_headless_it_serves_the_web_viewer_and_prints_a_url_that_answers(tiny_run, tmp_path):
    web, grpc = free_port(), free_port()
    log = tmp_path / "view.log"
    with open(log, "w") as err:
        server = subprocess.Popen(
            [sys.executable, str(VIEW), str(tiny_run), "--web-port", str(web), "--grpc-port",
             str(grpc), "--bind", "127.0.0.1"],
            stdout=subprocess.PIPE, stderr=err, text=True, env=headless(), start_new_session=True)
    try:
        line = server.stdout.readline()
        match = re.search(r"at (http://127\.0\.0\.1:\d+/\?url=\S+);", line)
        assert match, (line, log.read_text())
        assert str(tiny_run / "run.rrd") in line
        url = match.group(1)
        # The page reads the recording from its own origin (recording.one_origin).
        assert url == (f"http://127.0.0.1:{web}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{web}"
                       f"%2Fproxy")
        with urllib.request.urlopen(url, timeout=10) as page:
            assert page.status == 200 and b"<html" in page.read().lower()
        with socket.create_connection(("127.0.0.1", grpc), timeout=5):
            pass  # the gRPC server behind it
        # The recording sent, the server idles (given the file itself, it kept a core busy).
        [rerun] = descendants(server.pid)
        before = process_cpu(rerun)
        time.sleep(3.0)
        after = process_cpu(rerun)
        assert before is not None and after is not None and after[1] - before[1] < 0.5
        os.killpg(server.pid, signal.SIGINT)  # Ctrl-C in its terminal
        assert server.wait(timeout=10) == 0
        assert "Traceback" not in log.read_text()
    finally:
        if server.poll() is None:
            for pid in descendants(server.pid):  # the rerun server, in a session of its own
                os.kill(pid, signal.SIGKILL)
            os.killpg(server.pid, signal.SIGKILL)
            server.wait()
    for port in (web, grpc):  # the rerun server went with it
        assert not view.port_taken("127.0.0.1", port)


def test_a_recording_cut_off_mid_message_is_sent_under_its_own_ids(tiny_run, tmp_path):
    """A process killed mid-write leaves its part cut off: it is read as far as it goes."""
    run_id = SwarmConfig.from_json((tiny_run / "config.json").read_text()).run_id
    whole = (tiny_run / "run.rrd").read_bytes()
    cut = tmp_path / "cut.rrd"
    cut.write_bytes(whole[:len(whole) // 2 + 7])
    assert _recording_ids(tiny_run / "run.rrd") == _recording_ids(cut) == (APP_ID, run_id)
    cut.write_bytes(whole[:8])  # the header alone
    with pytest.raises(RecordingError, match="holds no recording"):
        _recording_ids(cut)


def test_a_run_directory_stands_for_its_recording_or_its_parts(tmp_path, tiny_run):
    assert view.recordings(tiny_run) == [tiny_run / "run.rrd"]
    assert view.recordings(tiny_run / "run.rrd") == [tiny_run / "run.rrd"]
    cut = tmp_path / "cut" / "rerun-parts"
    cut.mkdir(parents=True)
    for name in ("world.1.rrd", "agent-0.2.rrd"):
        (cut / name).write_bytes((tiny_run / "run.rrd").read_bytes())
    assert view.recordings(cut.parent) == [cut / "agent-0.2.rrd", cut / "world.1.rrd"]


@pytest.mark.parametrize("kind, message", [
    ("missing", "no such file or folder"),
    ("text", "is not a Rerun recording"),
    ("empty folder", "holds no recording"),
])
def test_what_is_not_a_recording_gives_one_line_and_exit_2(tmp_path, kind, message):
    path = tmp_path / "x"
    if kind == "text":
        path.write_text("hello\n")
    elif kind == "empty folder":
        path.mkdir()
    done = subprocess.run([sys.executable, str(VIEW), str(path)], capture_output=True, text=True,
                          env=headless(), timeout=60)
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and "Traceback" not in done.stderr


@pytest.mark.parametrize("environment, web, expected", [
    ({"DISPLAY": ":0"}, False, "native"),
    ({"WAYLAND_DISPLAY": "wayland-0"}, False, "native"),
    ({}, False, "web"),
    ({"DISPLAY": ":0"}, True, "web"),
])
def test_the_native_viewer_where_there_is_a_display_else_the_web_one(
        monkeypatch, tiny_run, environment, web, expected):
    monkeypatch.setattr(sys, "platform", "linux")
    for name in ("DISPLAY", "WAYLAND_DISPLAY"):
        monkeypatch.delenv(name, raising=False)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    chosen = []
    monkeypatch.setattr(view, "open_native", lambda files: chosen.append("native") or 0)
    monkeypatch.setattr(view, "serve_web", lambda *a: chosen.append("web") or 0)
    assert view.main([str(tiny_run), *(["--web"] if web else [])]) == 0
    assert chosen == [expected]


def test_a_taken_port_is_one_line(tiny_run):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        started = time.monotonic()
        done = subprocess.run([sys.executable, str(VIEW), str(tiny_run), "--web", "--bind",
                               "127.0.0.1", "--web-port", str(port)],
                              capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and f"port {port} is in use" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and time.monotonic() - started < 30
