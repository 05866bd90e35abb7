#!/usr/bin/env python3
"""Run a Zenoh router for a swarm that spans several machines (until Ctrl-C or SIGTERM).

    python launch/router.py --listen tcp/0.0.0.0:7447
    python launch/router.py --zenoh-config secure/router.json5   # made by launch/secure.py

The world and the agents then join it as clients (``--mode client --connect tcp/ROUTER:7447``),
and every message, agent-to-agent negotiation queries included, goes through the router
(docs/operations.md). zenoh-python's own router mode: no separate binary. Without ``--listen`` and
without a config file that lists endpoints, the router listens on ``tcp/0.0.0.0:7447``. Multicast
scouting is off unless the config file turns it on. When the router is up it prints one line
``router <zid> listening on <endpoints>`` on stdout; bad options or a failure to start (port in
use, unreadable certificate, ...) give one line on stderr and exit codes 2 and 1. Zenoh's own
log goes to stderr at level error, or at the level ``RUST_LOG`` gives (e.g. ``RUST_LOG=info``).
"""

import json
import re
import signal
import sys
import threading
from pathlib import Path


import zenoh

from nnql_swarm.launch.cli import OneLineParser
from nnql_swarm.transport.settings import TransportSettings

DEFAULT_LISTEN = "tcp/0.0.0.0:7447"
EXIT_FAILED = 1

_SOURCE_LOCATION = re.compile(r"\s+at \S+\.rs:\d+\.?")
_JSON5_MESSAGE = re.compile(r'Json5Err\(Message \{ msg: "(.*?)", location')


def one_line(error: Exception) -> str:
    """A Zenoh error as one readable line (without the Rust source locations it carries)."""
    text = _SOURCE_LOCATION.sub("", str(error))
    json5 = _JSON5_MESSAGE.search(text)
    return " ".join((json5.group(1) if json5 else text).split())


def check_endpoint(endpoint: str) -> str:
    """``endpoint`` if its port is 0..65535 (Zenoh checks the rest), else ValueError."""
    proto, _, address = endpoint.partition("/")
    address = re.split(r"[?#]", address, maxsplit=1)[0]
    if proto in ("tcp", "tls", "udp", "quic", "ws"):
        port = address.rpartition(":")[2]
        if not port.isdigit() or not 0 <= int(port) <= 65535:
            raise ValueError(f"invalid port in endpoint {endpoint!r}: expected 0..65535")
    return endpoint


def build_parser() -> OneLineParser:
    p = OneLineParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                   help=f"endpoint to listen on (repeatable; default {DEFAULT_LISTEN} "
                        "unless the config file lists some)")
    p.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                   help="another router to connect to (repeatable)")
    p.add_argument("--zenoh-config", default=None, metavar="FILE",
                   help="a Zenoh JSON5 config file (TLS, authentication, access control)")
    return p


def _endpoints(config: zenoh.Config, which: str) -> list[str]:
    """The router's ``listen`` or ``connect`` endpoints in a config (a list, or a per-mode dict)."""
    endpoints = json.loads(str(config)).get(which, {}).get("endpoints") or []
    if isinstance(endpoints, dict):
        endpoints = endpoints.get("router") or []
    return list(endpoints)


def settings(args) -> TransportSettings:
    """The router's session settings; the file's endpoints count unless overridden."""
    listen = list(args.listen)
    if not listen:
        in_file = []
        if args.zenoh_config:
            in_file = _endpoints(zenoh.Config.from_file(args.zenoh_config), "listen")
        if not in_file:
            listen = [DEFAULT_LISTEN]
    return TransportSettings(mode="router", listen=tuple(listen), connect=tuple(args.connect),
                             config_file=args.zenoh_config)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.zenoh_config and not Path(args.zenoh_config).is_file():
        parser.error(f"no Zenoh config file at {args.zenoh_config}")
    try:
        for endpoint in args.listen + args.connect:
            check_endpoint(endpoint)
        config = settings(args).zenoh_config()
    except Exception as error:  # a malformed endpoint or config file is the user's option
        parser.error(one_line(error))
    zenoh.init_log_from_env_or("error")
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    try:
        session = zenoh.open(config)
    except Exception as error:
        print(f"router.py: cannot start the router: {one_line(error)}", file=sys.stderr)
        return EXIT_FAILED
    with session:
        endpoints = _endpoints(config, "listen")
        print(f"router {session.info.zid()} listening on {', '.join(endpoints)}", flush=True)
        while not stop.wait(0.5):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main())
