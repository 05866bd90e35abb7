"""Watching from another machine: a browser in a network namespace of its own opens the URL that
``nnql-view --web`` printed in another, and must see the recording.

Two hosts on a private LAN (``tests/netns.py``: network namespaces joined by veths to one bridge,
nothing connected to this machine's own network): ``server``, where ``launch/view.py RUN --web
--bind <server's address>`` serves a saved run (a short in-process run of 8 agents), and
``viewer``, where headless Chromium runs (Playwright starts it through ``ip netns exec``, so its
only network is the viewer host's). The browser opens exactly the URL the command printed; the
page and its data come from one origin (``recording.one_origin``), the server's address, and
the pixels must show the run: the grid and every agent's colour (``tests.browser.check_run``),
as for the saved run opened on this machine.

The control, opened in the same browser at the same time: the same viewer page at the same
address with no recording named (Rerun's welcome screen); the check must fail on it.

Where the machine cannot make namespaces (no ``ip``, not root, a kernel or container that
refuses ``ip netns add``), the test is skipped saying so.
"""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.palette import agent_colors
from nnql_swarm.transport.ports import free_port
from tests import netns
from tests.browser import CHROMIUM, check_run, chromium, screenshot, wait_for
from tests.swarm_helpers import ROOT, run_swarm

pytestmark = [pytest.mark.browser, pytest.mark.full, pytest.mark.timeout(900)]

SIZE = (1600, 900)
LOAD_TIMEOUT = 300.0
"""Seconds the viewer gets to show the run (30 to 90 s on a busy 2-core machine)."""
SERVING_TIMEOUT = 60.0
LIGHT = "&persist=0&theme=light"
"""What the test adds to the printed URL: a fresh viewer, in the light theme the checks read."""

REASON = netns.unavailable_reason()


def inside(lan: netns.Lan, host: str, program: Path, folder: Path) -> Path:
    """A program (written in ``folder``) that runs ``program`` inside ``host``'s namespace, with
    the arguments and open files it was given (Playwright talks to Chromium over inherited
    pipes)."""
    wrapper = folder / f"{program.name}-in-{host}"
    wrapper.write_text(f'#!/bin/sh\nexec {" ".join(lan.command(host, [str(program)]))} "$@"\n')
    wrapper.chmod(0o755)
    return wrapper


def printed_url(log: Path, server: subprocess.Popen) -> str:
    deadline = time.monotonic() + SERVING_TIMEOUT
    while not (found := re.search(r"to the web viewer at (\S+);", log.read_text())):
        assert server.poll() is None, f"nnql-view ended: {log.read_text()}"
        assert time.monotonic() < deadline, f"nnql-view printed no URL: {log.read_text()}"
        time.sleep(0.5)
    return found.group(1)


@pytest.fixture(scope="module")
def remote(tmp_path_factory):
    """Screenshots of the printed URL and of the control, opened from the viewer host."""
    if REASON is not None:
        pytest.skip(f"no network namespaces: {REASON}")
    base = tmp_path_factory.mktemp("remote")
    done = run_swarm(base / "run", "--agents", "8", "--episodes", "3", "--max-steps", "30",
                     "--seed", "3", "--in-process")
    assert done.returncode == 0, done.stderr
    config = SwarmConfig.from_json((base / "run" / "config.json").read_text())
    shots, failure = {}, None
    with netns.Lan(["server", "viewer"]) as lan:
        web_port = free_port()
        log = base / "view.log"
        with open(log, "w") as out:
            server = lan.popen("server", [
                sys.executable, str(ROOT / "launch" / "view.py"), str(base / "run"), "--web",
                "--bind", lan.ip("server"), "--web-port", str(web_port),
                "--grpc-port", str(free_port())], stdout=out, stderr=subprocess.STDOUT)
        url = printed_url(log, server)
        with chromium(inside(lan, "viewer", CHROMIUM, base), size=SIZE) as browser:
            control = browser.new_page()
            control.goto(f"http://{lan.ip('server')}:{web_port}/?persist=0&theme=light")
            page = browser.new_page()
            page.goto(url + LIGHT)
            try:
                shots["printed"], _, _ = wait_for(
                    page, lambda image: check_run(image, config.width, config.height,
                                                  agent_colors(config.n_agents)),
                    LOAD_TIMEOUT, every=3.0)
            except AssertionError as error:
                failure = str(error)
                shots["printed"] = screenshot(page)
            screenshot(page, base / "printed.png")
            shots["control"] = screenshot(control, base / "control.png")
        os.killpg(server.pid, signal.SIGINT)
        server.wait(timeout=30)
        served = log.read_text()
    print(f"remote browser test: screenshots in {base}")
    return {"shots": shots, "failure": failure, "config": config, "url": url, "lan": lan,
            "served": served, "server_code": server.returncode}


def test_the_printed_url_names_the_servers_address(remote):
    lan = remote["lan"]
    assert remote["url"].startswith(f"http://{lan.ip('server')}:")
    assert "127.0.0.1" not in remote["url"] and "localhost" not in remote["url"]


def test_the_printed_url_shows_the_run_in_a_browser_on_another_host(remote):
    assert remote["failure"] is None, remote["failure"]
    config = remote["config"]
    check_run(remote["shots"]["printed"], config.width, config.height,
              agent_colors(config.n_agents))


def test_the_check_fails_on_the_viewer_without_the_recording(remote):
    if remote["failure"] is not None:
        pytest.fail("the run itself never showed, so a failing check proves nothing here")
    config = remote["config"]
    with pytest.raises(AssertionError, match="no 11x11 grid"):
        check_run(remote["shots"]["control"], config.width, config.height,
                  agent_colors(config.n_agents))


def test_the_server_stops_cleanly_on_ctrl_c(remote):
    """Exit code 0 and no traceback, though the page's stream was cut in the middle."""
    assert remote["server_code"] == 0, remote["served"]
    assert "Traceback" not in remote["served"], remote["served"]
