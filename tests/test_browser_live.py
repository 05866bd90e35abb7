"""Watching in a real browser, live and from elsewhere: each way of watching a run, opened in
headless Chromium, must show the designed first view (``recording.blueprint``), found by where
the world view is and how large (``tests.browser.check_layout``), with every agent in it.

Three ways, each a real run on this machine: ``--rerun-serve-web`` (an in-process run of 8
agents; the launcher serves the web viewer), ``--rerun-connect`` (a distributed run of 4 agents,
the world and every agent streaming to a viewer already running: a ``rerun --serve-web`` started
with nothing in it) and ``nnql-view --web`` on that run's ``run.rrd``. ``--rerun-spawn`` streams
as ``--rerun-connect`` does, to the native viewer it starts, which needs a display.

The URLs ``--rerun-serve-web`` and ``nnql-view`` print for other machines are opened as printed,
at this machine's own address (its outgoing interface's, not loopback), as another machine would
open them: the page and its data then come from one origin (``recording.one_origin``).

Two controls, opened in the same browser at the same time, on which the checks must fail: the
same recording without its blueprint (under another application id, so that the viewer lays it
out itself), and the page at this machine's address reading Rerun's gRPC server across origins,
as the printed URL used to (the server refuses the page: Rerun's welcome screen).
"""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

import pytest
import rerun as rr
from PIL import Image

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.viewers import grpc_url, public_host
from nnql_swarm.transport.ports import free_port
from nnql_swarm.recording.palette import agent_colors
from tests.browser import (
    Viewer, check_layout, check_run, chromium, screenshot, wait_for, web_viewer,
)
from tests.swarm_helpers import ROOT, run_swarm, start_swarm

pytestmark = [pytest.mark.browser, pytest.mark.timeout(900)]

COMMON = ("--episodes", "3", "--max-steps", "30", "--seed", "3")
SIZE = (1600, 900)
LOAD_TIMEOUT = 240.0
"""Seconds the viewer gets to show a run (30 to 90 s on a busy 2-core machine)."""
SERVING_TIMEOUT = 180.0


LIGHT = "&persist=0&theme=light"
"""What the tests add to a printed URL: a fresh viewer, in the light theme the checks read."""


def wait_for_line(process_text, pattern: str, alive, what: str) -> re.Match:
    """The first match of ``pattern`` in what a process wrote, once it is there."""
    deadline = time.monotonic() + SERVING_TIMEOUT
    while not (found := re.search(pattern, process_text())):
        assert alive(), f"{what} ended: {process_text()}"
        assert time.monotonic() < deadline, f"{what} printed no URL: {process_text()}"
        time.sleep(1)
    return found


def serving_run(out):
    """An in-process run with ``--rerun-serve-web`` on free ports, once it serves the whole
    run; returns the process, its ports and the URL it printed for other machines."""
    viewer = Viewer(web_port=free_port(), grpc_port=free_port())
    swarm = start_swarm(out, "--agents", "8", *COMMON, "--in-process", "--rerun-serve-web",
                        "--rerun-port", str(viewer.grpc_port),
                        "--rerun-web-port", str(viewer.web_port))
    wait_for_line(swarm.stderr_text, "still serving", lambda: swarm.poll() is None,
                  "--rerun-serve-web")
    printed = re.search(r"rerun: web viewer at (\S+)", swarm.stderr_text()).group(1)
    return swarm, viewer, printed


def serving_saved(run_dir: Path, log: Path):
    """``nnql-view --web`` on every interface, serving ``run_dir``; the process and the URL it
    printed for other machines."""
    command = [sys.executable, str(ROOT / "launch" / "view.py"), str(run_dir), "--web",
               "--web-port", str(free_port()), "--grpc-port", str(free_port())]
    with open(log, "w") as out:
        server = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT,
                                  start_new_session=True)
    found = wait_for_line(log.read_text, r"to the web viewer at (\S+) \(on this machine",
                          lambda: server.poll() is None, "nnql-view")
    return server, found.group(1)


def shows_run(image, config) -> None:
    """The designed layout, with the run in it: every agent's colour in the world view."""
    check_layout(image, config)
    check_run(image, config.width, config.height, agent_colors(config.n_agents))


@pytest.fixture(scope="module")
def pictures(tmp_path_factory):
    """Screenshots of each way of watching once it shows the run, and of the controls then."""
    base = tmp_path_factory.mktemp("live")
    shots, failures, configs, urls = {}, {}, {}, {}
    host = public_host()
    assert not host.startswith("127."), "this machine has no address but loopback to test from"
    swarm, served, urls["serve-web"] = serving_run(base / "serve-web")
    saved = None
    try:
        with web_viewer(None, log=base / "connect.log") as running, \
                web_viewer(None, log=base / "plain.log") as plain, chromium(size=SIZE) as browser:
            done = run_swarm(base / "connect", "--agents", "4", *COMMON,
                             "--rerun-connect", grpc_url(running.grpc_port))
            assert done.returncode == 0, done.stderr
            urls["connect"] = running.url()
            saved, urls["view"] = serving_saved(base / "connect", base / "view.log")
            # The controls: the same recording without its blueprint, and the page at this
            # machine's address reading the gRPC server across origins, as it used to.
            stream = rr.RecordingStream("nnql-swarm-without-blueprint", recording_id="plain")
            stream.connect_grpc(grpc_url(plain.grpc_port))
            stream.send_chunks(rr.chunk.RrdReader(base / "connect" / "run.rrd").store())
            stream.flush()
            controls = {"plain": plain.url(),
                        "cross-origin": f"http://{host}:{served.web_port}/?url="
                                        f"{quote(grpc_url(served.grpc_port, host), safe='')}{LIGHT}"}
            pages = {}
            for name, url in controls.items():
                pages[name] = browser.new_page()
                pages[name].goto(url)
            for name in ("serve-web", "connect", "view"):
                configs[name] = SwarmConfig.from_json(
                    (base / ("serve-web" if name == "serve-web" else "connect")
                     / "config.json").read_text())
                page = browser.new_page()
                page.goto(urls[name] + ("" if name == "connect" else LIGHT))
                try:
                    shots[name], _, _ = wait_for(
                        page, lambda image: shows_run(image, configs[name]), LOAD_TIMEOUT,
                        every=3.0)
                    Image.fromarray(shots[name]).save(base / f"{name}.png")
                except AssertionError as error:
                    failures[name] = str(error)
                    shots[name] = screenshot(page, base / f"{name}.png")
                page.close()
            for name, page in pages.items():
                shots[name] = screenshot(page, base / f"{name}.png")
            stream.disconnect()
    finally:
        for process in (swarm, saved):
            if process is not None:
                os.killpg(process.pid, signal.SIGINT)
                process.wait(timeout=30)
    print(f"live browser test: screenshots in {base}")
    return {"shots": shots, "failures": failures, "configs": configs, "urls": urls,
            "host": host}


def test_the_printed_urls_name_this_machine_as_others_reach_it(pictures):
    for name in ("serve-web", "view"):
        assert pictures["urls"][name].startswith(f"http://{pictures['host']}:")


@pytest.mark.parametrize("how", ["serve-web", "view"])
def test_the_printed_url_shows_the_run_from_this_machines_address(pictures, how):
    """Opened at this machine's address, not loopback: the page and its data on one origin."""
    assert how not in pictures["failures"], pictures["failures"][how]
    config = pictures["configs"][how]
    check_run(pictures["shots"][how], config.width, config.height, agent_colors(config.n_agents))


def test_reading_the_grpc_server_across_origins_shows_nothing(pictures):
    """The control: what the printed URL used to be; Rerun's gRPC server refuses the page."""
    if pictures["failures"]:
        pytest.fail("a run itself never showed, so a failing check proves nothing here")
    config = pictures["configs"]["serve-web"]
    with pytest.raises(AssertionError, match="no 11x11 grid"):
        check_run(pictures["shots"]["cross-origin"], config.width, config.height,
                  agent_colors(config.n_agents))


@pytest.mark.parametrize("how", ["serve-web", "connect", "view"])
def test_every_way_of_watching_opens_on_the_designed_layout(pictures, how):
    assert how not in pictures["failures"], pictures["failures"][how]
    config = pictures["configs"][how]
    grid = check_layout(pictures["shots"][how], config)
    assert grid.box[2] - grid.box[0] > 40 * config.width
    check_run(pictures["shots"][how], config.width, config.height, agent_colors(config.n_agents))


def test_the_layout_check_fails_on_the_viewers_own_layout(pictures):
    if pictures["failures"]:
        pytest.fail("a live run itself never showed, so a failing check proves nothing here")
    with pytest.raises(AssertionError, match="not the designed layout|no 11x11 grid"):
        check_layout(pictures["shots"]["plain"], pictures["configs"]["connect"])
