"""TCP ports on this machine: a free one to listen on, and waiting for a listener."""

import itertools
import os
import socket
import time

LOWEST_CHOSEN_PORT = 10_000
"""The lowest port :func:`free_port` picks (below it: well-known and registered services)."""

_PORT_RANGE_FILE = "/proc/sys/net/ipv4/ip_local_port_range"
_PORT_TRIES = itertools.count()


def _ephemeral_low() -> int:
    """The lowest port the kernel hands out for port 0 and outgoing connections."""
    try:
        with open(_PORT_RANGE_FILE) as f:
            return int(f.read().split()[0])
    except (OSError, ValueError, IndexError):
        return 32768  # Linux's default; elsewhere a guess


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port that nobody listens on right now, below the kernel's ephemeral range.

    A port from that range (a bind to port 0) could be handed, before its owner binds it, to
    another process of the same run that binds port 0 (a mesh agent's listener) or connects
    out. Below the range only an explicit bind can take it. Each process searches from a place
    derived from its id, so that processes choosing at once start apart, and each call goes on
    from where the last stopped, so that one process choosing several ports gets different
    ones; where the range leaves no room below it, the kernel chooses.
    """
    span = _ephemeral_low() - LOWEST_CHOSEN_PORT
    for _ in range(max(span, 0)):
        port = LOWEST_CHOSEN_PORT + (os.getpid() * 7919 + next(_PORT_TRIES)) % span
        with socket.socket() as s:
            try:
                s.bind((host, port))
            except OSError:
                continue
            return port
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def wait_listening(host: str, port: int, timeout_s: float = 30.0) -> bool:
    """Until something accepts TCP connections on ``host:port`` (a hub's Zenoh listener);
    False if nothing did within ``timeout_s``. A client of the hub connects then at once, rather
    than at Zenoh's next retry (``connect_timeout_s``), a second or more later."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            socket.create_connection((host, port), timeout=1.0).close()
            return True
        except OSError:
            time.sleep(0.05)
    return False
