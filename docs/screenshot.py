#!/usr/bin/env python3
"""The pictures of the viewer in the docs: recordings served by the web viewer, in headless
Chromium.

Needs Debian's ``chromium`` and the ``browser`` extra (Playwright): ``make playwright chromium``.
The web viewer renders with SwiftShader; a recording of a few MB shows after a minute or two.

    python docs/screenshot.py --docs

makes the four runs of the docs and their pictures: the default run (``launch/swarm.py``, 8
agents, distributed, with the paper's QL as the curves' reference) as ``docs/viewer.png``, the
README's; 8 agents with walls (``--obstacle-density 0.2``, the reference too) as
``docs/viewer-walls.png``; 64 agents on 32 x 32 as ``docs/viewer-64.png``; 128 agents on
40 x 40 as ``docs/viewer-128.png``; 8 agents in a 15 x 15 maze (``--map maze:15x15``), where
agents end short of their goals, as ``docs/viewer-maze.png`` (``--in-process``, the same runs
as distributed); 64 agents in a 32 x 32 maze, episodes of 256 steps (10 episodes), each agent's
path faded by age, as ``docs/viewer-crowded.png``; 8 agents in a lifelong run (``--tasks lifelong``, 30 episodes, distributed) as
``docs/viewer-lifelong.png``; from the default run, agent 0 followed on the ``tick`` timeline as
``docs/viewer-follow.png`` and the learning curves alone as ``docs/viewer-curves.png``
(``recording.follow``). ``--only PICTURE...`` takes only those. The runs go to
``runs/screenshots/``. Each picture is taken once the viewer shows what ``tests/browser.py``
checks of the newest episode (the grid, walls, labels, moves and waits), or after ``--wait``.

    python docs/screenshot.py runs/<id>/run.rrd picture.png

takes one picture of a saved run.
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from tests.browser import CHROMIUM, check_world, chromium, wait_for, web_viewer  # noqa: E402

DOCS_RUNS = {
    "viewer.png": ("default", ["--agents", "8", "--reference"]),
    "viewer-walls.png": ("walls", ["--agents", "8", "--obstacle-density", "0.2", "--in-process",
                                   "--reference"]),
    "viewer-64.png": ("64-agents", ["--agents", "64", "--grid", "32x32", "--in-process"]),
    "viewer-128.png": ("128-agents", ["--agents", "128", "--grid", "40x40", "--in-process"]),
    "viewer-maze.png": ("maze", ["--agents", "8", "--map", "maze:15x15", "--in-process"]),
    "viewer-crowded.png": ("64-maze", ["--agents", "64", "--map", "maze:32x32:3", "--max-steps",
                                       "256", "--episodes", "10", "--in-process"]),
    "viewer-lifelong.png": ("lifelong", ["--agents", "8", "--tasks", "lifelong", "--episodes",
                                         "30"]),
    "viewer-follow.png": ("default", ["--agents", "8", "--reference"]),
    "viewer-curves.png": ("default", ["--agents", "8", "--reference"]),
}
"""Each picture of the docs: its run's id under ``runs/screenshots/`` and options."""

VIEWS = {"viewer-follow.png": "follow", "viewer-curves.png": "curves"}
"""The pictures of a copy of their run that opens on another view (``recording.follow``):
agent 0 followed on the ``tick`` timeline, a third into the last episode (the world's ticks of
that episode only, so that the viewer has them soon); the learning curves
alone. The viewer shows them after ``FIXED_WAIT`` seconds (the world view's checks are those of
the ``episode`` view)."""
FIXED_WAIT = 120.0


def take(browser, recording: Path, png: Path, wait: float, run_dir: Path | None = None) -> str:
    """Open ``recording`` in a new page; screenshot it to ``png`` once the world view passes
    ``check_world`` (with ``run_dir``), or after ``wait`` seconds. Returns what it saw."""
    from PIL import Image

    from nnql_swarm.protocol.config import SwarmConfig

    with web_viewer(recording) as viewer:
        page = browser.new_page()
        page.goto(viewer.url())
        if run_dir is None:
            time.sleep(wait)
            png.write_bytes(page.screenshot(timeout=120_000))
            seen = f"after {wait:.0f} s"
        else:
            config = SwarmConfig.from_json((run_dir / "config.json").read_text())
            try:
                image, found, seconds = wait_for(page, lambda im: check_world(im, config, run_dir),
                                                 wait, every=3.0)
                time.sleep(3)  # the last chunks of plots and heat maps
                png.write_bytes(page.screenshot(timeout=120_000))
                seen = f"checks passed after {seconds:.0f} s: " + ", ".join(
                    f"{key} {value}" for key, value in found.items() if key != "grid")
            except AssertionError as failure:
                png.write_bytes(page.screenshot(timeout=120_000))
                seen = f"CHECKS FAILED: {failure}"
        page.close()
    # A palette of at most 256 colours keeps the picture small and exact enough for text.
    Image.open(png).convert("RGB").quantize(256, dither=Image.Dither.NONE).save(png,
                                                                                optimize=True)
    return seen


def other_view(run_dir: Path, view: str) -> Path:
    """A copy of the run's recording that opens on ``view`` (:data:`VIEWS`)."""
    from nnql_swarm.recording.follow import curves_copy, follow_copy
    from nnql_swarm.world.metrics import read_episodes

    copy = run_dir / f"{view}.rrd"
    if view == "curves":
        return curves_copy(run_dir, copy)
    last = read_episodes(run_dir / "episodes.csv")[-1]
    start = int(last["end_tick"]) - int(last["steps"])
    return follow_copy(run_dir, copy, 0, start + int(last["steps"]) // 3, since=start)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("recording", type=Path, nargs="?")
    p.add_argument("png", type=Path, nargs="?")
    p.add_argument("--docs", action="store_true", help="make the docs' runs and pictures")
    p.add_argument("--size", default="1600x900", help="viewport WIDTHxHEIGHT")
    p.add_argument("--wait", type=float, default=300.0,
                   help="seconds to let the viewer load (a saved recording: the time it gets; "
                        "--docs: the most it waits for the checks)")
    p.add_argument("--chromium", type=Path, default=CHROMIUM)
    p.add_argument("--only", nargs="+", choices=tuple(DOCS_RUNS), help="with --docs: only these")
    args = p.parse_args()
    if not args.docs and (args.recording is None or args.png is None):
        p.error("give a recording and a picture, or --docs")

    width, height = (int(v) for v in args.size.split("x"))
    with chromium(args.chromium, size=(width, height)) as browser:
        if not args.docs:
            args.png.parent.mkdir(parents=True, exist_ok=True)
            print(f"{args.png}: {take(browser, args.recording, args.png, args.wait)}")
            return 0
        for picture, (run_id, options) in DOCS_RUNS.items():
            if args.only and picture not in args.only:
                continue
            out = ROOT / "runs" / "screenshots" / run_id
            if not (out / "run.rrd").exists():
                subprocess.run([sys.executable, str(ROOT / "launch" / "swarm.py"), *options,
                                "--run-id", run_id, "--out", str(out)], check=True,
                               stdout=subprocess.DEVNULL)
            png = ROOT / "docs" / picture
            if picture in VIEWS:
                copy = other_view(out, VIEWS[picture])
                print(f"{png}: {take(browser, copy, png, FIXED_WAIT)}", flush=True)
                continue
            print(f"{png}: {take(browser, out / 'run.rrd', png, args.wait, out)}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
