#!/usr/bin/env python3
"""The README's picture of the viewer: a recording served by the web viewer, in headless Chromium.

Needs Debian's ``chromium`` and Playwright for Python (``pip install playwright``; only for this
script, not a project dependency). DESIGN §8: the web viewer renders with SwiftShader after about
20 s of loading.

    python docs/screenshot.py runs/<id>/run.rrd docs/viewer.png --wait 320 --click 1375,886

A saved recording opens at its end (the blueprint follows the newest data); ``--click`` on the
time slider moves the time cursor (1375,886 at the default size is about 90 % of the run).
"""

import argparse
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from launch.recording import (  # noqa: E402
    grpc_url, rerun_binary, stop_process, wait_until_reachable,
)
from protocol.transport import free_port  # noqa: E402

CHROMIUM_ARGS = ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                 "--disable-background-networking"]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("recording", type=Path)
    p.add_argument("png", type=Path)
    p.add_argument("--size", default="1600x900", help="viewport WIDTHxHEIGHT")
    p.add_argument("--wait", type=float, default=25.0,
                   help="seconds to let the viewer load (minutes for a few MB on SwiftShader)")
    p.add_argument("--chromium", default="/usr/bin/chromium")
    p.add_argument("--click", default=None, metavar="X,Y",
                   help="once loaded, click there (e.g. on the time slider to move the cursor)")
    args = p.parse_args()
    from playwright.sync_api import sync_playwright

    width, height = (int(v) for v in args.size.split("x"))
    grpc_port, web_port = free_port(), free_port()
    server = subprocess.Popen(
        [*rerun_binary(), "--serve-web", "--port", str(grpc_port), "--web-viewer-port",
         str(web_port), str(args.recording)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        if not wait_until_reachable(grpc_url(grpc_port)):
            raise SystemExit("rerun --serve-web did not start")
        url = f"http://127.0.0.1:{web_port}/?url={quote(grpc_url(grpc_port), safe='')}"
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=args.chromium, args=CHROMIUM_ARGS)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url)
            time.sleep(args.wait)
            if args.click:
                x, y = (float(v) for v in args.click.split(","))
                page.mouse.click(x, y)  # e.g. on the time panel, to move the time cursor there
                time.sleep(5)
            args.png.parent.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(args.png))
            browser.close()
    finally:
        stop_process(server)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
