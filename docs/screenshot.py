#!/usr/bin/env python3
"""The README's picture of the viewer: a recording served by the web viewer, in headless Chromium.

Needs Debian's ``chromium`` and the ``browser`` extra (Playwright): ``make playwright chromium``.
The web viewer renders with SwiftShader after about 20 s of loading; a recording of a few MB
takes minutes more.

    python docs/screenshot.py runs/<id>/run.rrd docs/viewer.png --wait 320 --click 1375,886

A saved recording opens at its end (the blueprint follows the newest data); ``--click`` on the
time slider moves the time cursor (1375,886 at the default size is about 90 % of the run).
"""

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tests.browser import CHROMIUM, chromium, web_viewer  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("recording", type=Path)
    p.add_argument("png", type=Path)
    p.add_argument("--size", default="1600x900", help="viewport WIDTHxHEIGHT")
    p.add_argument("--wait", type=float, default=25.0,
                   help="seconds to let the viewer load (minutes for a few MB on SwiftShader)")
    p.add_argument("--chromium", type=Path, default=CHROMIUM)
    p.add_argument("--click", default=None, metavar="X,Y",
                   help="once loaded, click there (e.g. on the time slider to move the cursor)")
    args = p.parse_args()

    width, height = (int(v) for v in args.size.split("x"))
    with web_viewer(args.recording) as viewer, \
            chromium(args.chromium, size=(width, height)) as browser:
        page = browser.new_page()
        page.goto(viewer.url())
        time.sleep(args.wait)
        if args.click:
            x, y = (float(v) for v in args.click.split(","))
            page.mouse.click(x, y)
            time.sleep(5)
        args.png.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(args.png))
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
