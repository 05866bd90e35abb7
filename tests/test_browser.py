"""The web viewer in a real browser: a short real run, served by ``rerun --serve-web``, opened in
headless Chromium; the screenshot's pixels must show the grid and every agent's colour in it.

The same checks must fail on a blank page and on the viewer when the recording does not come
(a gRPC port nobody serves: the viewer shows its welcome page), opened in the same browser at the
same time as the real one, so that it had as long to load.
"""

import time

import pytest
from PIL import Image

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.transport import free_port
from tests.browser import (
    BACKGROUND, check_run, chromium, near, screenshot, wait_for, web_viewer,
)
from tests.swarm_helpers import run_swarm
from nnql_swarm.world.viz import agent_colors

pytestmark = [pytest.mark.browser, pytest.mark.timeout(420)]

RUN = ("--agents", "4", "--episodes", "1", "--max-steps", "20", "--seed", "3", "--in-process")
LOAD_TIMEOUT = 240.0
"""Seconds the viewer gets to show the run (it took 30 to 45 s on a busy 2-core machine)."""


@pytest.fixture(scope="module")
def pictures(tmp_path_factory):
    """Screenshots of the run in the viewer, once it shows, and of a broken and a blank page at
    that moment; the seconds each step took; the run's config."""
    base = tmp_path_factory.mktemp("browser")
    start = time.monotonic()
    result = run_swarm(base / "run", *RUN, "--run-id", "browser")
    assert result.returncode == 0, result.stderr
    config = SwarmConfig.from_json((base / "run" / "config.json").read_text())
    colours = agent_colors(config.n_agents)
    seconds = {"record": time.monotonic() - start}
    with web_viewer(base / "run" / "run.rrd", log=base / "serve-web.log") as viewer, \
            chromium() as browser:
        run_page, broken_page, blank_page = (browser.new_page() for _ in range(3))
        run_page.goto(viewer.url())
        broken_page.goto(viewer.url(grpc_port=free_port()))
        blank_page.goto("about:blank")
        failure = None
        try:
            run, _, seconds["render"] = wait_for(
                run_page, lambda image: check_run(image, config.width, config.height, colours),
                LOAD_TIMEOUT, every=2.0)
            Image.fromarray(run).save(base / "run.png")
        except AssertionError as error:
            failure = str(error)
            run = screenshot(run_page, base / "run.png")
        broken = screenshot(broken_page, base / "broken.png")
        blank = screenshot(blank_page, base / "blank.png")
    seconds["total"] = time.monotonic() - start
    print(f"browser test: {seconds}, screenshots in {base}")
    return {"run": run, "failure": failure, "broken": broken, "blank": blank, "config": config,
            "colours": colours, "seconds": seconds}


def test_the_viewer_shows_the_grid_and_every_agents_colour(pictures):
    assert pictures["failure"] is None, pictures["failure"]
    config = pictures["config"]
    found = check_run(pictures["run"], config.width, config.height, pictures["colours"])
    x0, y0, x1, y1 = found["grid"]
    assert x1 - x0 > 10 * config.width and y1 - y0 > 10 * config.height  # a readable grid
    assert len(found["pixels"]) == config.n_agents


def test_the_checks_fail_on_a_blank_or_broken_page(pictures):
    if pictures["failure"] is not None:
        pytest.fail("the run itself never showed, so failing checks prove nothing here")
    config, colours = pictures["config"], pictures["colours"]
    grid = f"no {config.width}x{config.height} grid"
    for page in ("broken", "blank"):
        with pytest.raises(AssertionError, match=grid):
            check_run(pictures[page], config.width, config.height, colours)
    # The broken page is the viewer's own interface (light theme), not its dark loading screen.
    assert near(pictures["broken"], BACKGROUND, 12).mean() > 0.3
    # In the run's picture, colours that are none of the agents' are not found.
    others = agent_colors(2 * config.n_agents)[1::2]
    with pytest.raises(AssertionError, match="too few pixels"):
        check_run(pictures["run"], config.width, config.height, others)
