"""A tiny Zenoh process for topology and security tests: a hub, a queryable, or an asker.

    python tests/zenoh_probe.py hub   --mode router --listen tcp/10.213.7.1:7447 --seconds 60
    python tests/zenoh_probe.py serve --mode client --connect tcp/10.213.7.1:7447 --key k/a
    python tests/zenoh_probe.py ask   --mode client --connect tcp/10.213.7.1:7447 --key k/a

``hub`` and ``serve`` print ``ready`` once up and stay until SIGTERM (or ``--seconds``); ``ask``
sends ``get`` on the key for ``--seconds`` (stopping at ``--wanted`` answers) and prints one JSON
line: ``{"answers": n, "asked": m, "median_ms": ...}``. Multicast scouting is always off.
"""

import argparse
import json
import signal
import statistics
import sys
import threading
import time

import zenoh


def session_config(args) -> zenoh.Config:
    config = zenoh.Config.from_file(args.config) if args.config else zenoh.Config()
    config.insert_json5("mode", json.dumps(args.mode))
    if args.listen or not args.config:
        config.insert_json5("listen/endpoints", json.dumps(args.listen))
    if args.connect or not args.config:
        config.insert_json5("connect/endpoints", json.dumps(args.connect))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("role", choices=("hub", "serve", "ask"))
    p.add_argument("--mode", default="peer")
    p.add_argument("--listen", action="append", default=[])
    p.add_argument("--connect", action="append", default=[])
    p.add_argument("--config", default=None)
    p.add_argument("--key", default="probe/q")
    p.add_argument("--seconds", type=float, default=60.0)
    p.add_argument("--wanted", type=int, default=1)
    p.add_argument("--timeout", type=float, default=0.5, help="per get")
    args = p.parse_args()
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with zenoh.open(session_config(args)) as session:
        if args.role in ("hub", "serve"):
            if args.role == "serve":
                session.declare_queryable(args.key, lambda q: q.reply(q.key_expr, b"here"))
            print("ready", flush=True)
            stop.wait(args.seconds)
            return 0
        rtts, asked = [], 0
        deadline = time.monotonic() + args.seconds
        while time.monotonic() < deadline and len(rtts) < args.wanted and not stop.is_set():
            asked += 1
            start = time.perf_counter()
            replies = session.get(args.key, timeout=args.timeout)
            answered = any(reply.ok is not None for reply in replies)
            if answered:
                rtts.append((time.perf_counter() - start) * 1000)
            else:
                time.sleep(0.05)
        print(json.dumps({"answers": len(rtts), "asked": asked,
                          "median_ms": statistics.median(rtts) if rtts else None}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
