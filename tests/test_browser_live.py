"""Live viewing in a real browser: a run streamed as it goes, opened in headless Chromium, must
show the designed first view (``recording.blueprint``), as a saved run opened with ``nnql-view``
does, found by where the world view is and how large (``tests.browser.check_layout``).

Two ways of watching, each a real run on loopback: ``--rerun-serve-web`` (an in-process run of
8 agents; the launcher serves the web viewer) and ``--rerun-connect`` (a distributed run of 4
agents, the world and every agent streaming to a viewer already running: a ``rerun
--serve-web`` started with nothing in it). ``--rerun-spawn`` streams the same way as
``--rerun-connect``, to the native viewer it starts, which needs a display.

The check must fail on the same recording without its blueprint (sent under another application
id, so that the viewer lays it out itself), opened in the same browser at the same time.
"""

import signal
import time

import pytest
import rerun as rr
from PIL import Image

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.viewers import grpc_url
from nnql_swarm.transport.ports import free_port
from nnql_swarm.recording.palette import agent_colors
from tests.browser import (
    Viewer, check_layout, check_run, chromium, screenshot, wait_for, web_viewer,
)
from tests.swarm_helpers import run_swarm, start_swarm

pytestmark = [pytest.mark.browser, pytest.mark.timeout(900)]

COMMON = ("--episodes", "3", "--max-steps", "30", "--seed", "3")
SIZE = (1600, 900)
LOAD_TIMEOUT = 240.0
"""Seconds the viewer gets to show a run (30 to 90 s on a busy 2-core machine)."""
SERVING_TIMEOUT = 180.0


def serving_run(out):
    """An in-process run with ``--rerun-serve-web`` on free ports, once it serves the whole
    run; returns the process and the viewer it serves."""
    viewer = Viewer(web_port=free_port(), grpc_port=free_port())
    swarm = start_swarm(out, "--agents", "8", *COMMON, "--in-process", "--rerun-serve-web",
                        "--rerun-port", str(viewer.grpc_port),
                        "--rerun-web-port", str(viewer.web_port))
    deadline = time.monotonic() + SERVING_TIMEOUT
    while "still serving" not in swarm.stderr_text():
        assert swarm.poll() is None, swarm.stderr_text()
        assert time.monotonic() < deadline, swarm.stderr_text()
        time.sleep(1)
    return swarm, viewer


def shows_run(image, config) -> None:
    """The designed layout, with the run in it: every agent's colour in the world view."""
    check_layout(image, config)
    check_run(image, config.width, config.height, agent_colors(config.n_agents))


@pytest.fixture(scope="module")
def pictures(tmp_path_factory):
    base = tmp_path_factory.mktemp("live")
    shots, failures, configs = {}, {}, {}
    swarm, served = serving_run(base / "serve-web")
    try:
        with web_viewer(None, log=base / "connect.log") as running, \
                web_viewer(None, log=base / "plain.log") as plain, chromium(size=SIZE) as browser:
            done = run_swarm(base / "connect", "--agents", "4", *COMMON,
                             "--rerun-connect", grpc_url(running.grpc_port))
            assert done.returncode == 0, done.stderr
            # The control: the same recording, without its blueprint.
            stream = rr.RecordingStream("nnql-swarm-without-blueprint", recording_id="plain")
            stream.connect_grpc(grpc_url(plain.grpc_port))
            stream.send_chunks(rr.chunk.RrdReader(base / "connect" / "run.rrd").store())
            stream.flush()
            control = browser.new_page()
            control.goto(plain.url())
            for name, viewer in (("serve-web", served), ("connect", running)):
                configs[name] = SwarmConfig.from_json((base / name / "config.json").read_text())
                page = browser.new_page()
                page.goto(viewer.url())
                try:
                    shots[name], _, _ = wait_for(
                        page, lambda image: shows_run(image, configs[name]), LOAD_TIMEOUT,
                        every=3.0)
                    Image.fromarray(shots[name]).save(base / f"{name}.png")
                except AssertionError as error:
                    failures[name] = str(error)
                    shots[name] = screenshot(page, base / f"{name}.png")
                page.close()
            shots["control"] = screenshot(control, base / "control.png")
            stream.disconnect()
    finally:
        swarm.send_signal(signal.SIGINT)
        swarm.wait(timeout=30)
    print(f"live browser test: screenshots in {base}")
    return {"shots": shots, "failures": failures, "configs": configs}


@pytest.mark.parametrize("how", ["serve-web", "connect"])
def test_a_live_run_opens_on_the_designed_layout(pictures, how):
    assert how not in pictures["failures"], pictures["failures"][how]
    config = pictures["configs"][how]
    grid = check_layout(pictures["shots"][how], config)
    assert grid.box[2] - grid.box[0] > 40 * config.width
    check_run(pictures["shots"][how], config.width, config.height, agent_colors(config.n_agents))


def test_the_layout_check_fails_on_the_viewers_own_layout(pictures):
    if pictures["failures"]:
        pytest.fail("a live run itself never showed, so a failing check proves nothing here")
    with pytest.raises(AssertionError, match="not the designed layout|no 11x11 grid"):
        check_layout(pictures["shots"]["control"], pictures["configs"]["connect"])
