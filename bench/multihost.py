#!/usr/bin/env python3
"""Zenoh layouts across hosts: query round trips and swarm ticks per second (needs root: netns).

Three network namespaces on one private bridge stand in for three machines (tests/netns.py):
``world`` (the world, the router), ``a`` (the first half of the agents), ``b`` (the rest).
Measured per layout:

- ``get_ms``: the median round trip of a ``get`` from a process on host b to a queryable on host a
  (tests/zenoh_probe.py, 2000 queries), i.e. one negotiation question across hosts;
- ``ticks_per_s``: the swarm's tick rate, ``--agents`` agents (8; on the grid of
  ``bench/scale.py`` for their number), from the world's ``episodes.csv`` (all ticks over all
  episode durations; start-up excluded), and whether every intent arrived.

Layouts: ``router`` (everyone a client of launch/router.py), ``secured`` (the same through the
mTLS + password + access-control router of launch/secure.py), ``mesh`` (peers; every agent listens
on its host's address, gossip connects them all), ``world-hub`` (the world a peer, the agents its
clients: the world relays), and ``one-host`` (the default embedded layout, all in host world).

    sudo .venv/bin/python -m bench.multihost --episodes 20 --repeats 3
    sudo .venv/bin/python -m bench.multihost --agents 64 --layouts router --episodes 5 --repeats 1
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
from bench.harness import grid_side
from tests import netns
from nnql_swarm.world.metrics import read_episodes

PY = sys.executable
SWARM, ROUTER = str(ROOT / "launch" / "swarm.py"), str(ROOT / "launch" / "router.py")
SECURE, PROBE = str(ROOT / "launch" / "secure.py"), str(ROOT / "tests" / "zenoh_probe.py")
LAYOUTS = ("router", "secured", "mesh", "world-hub", "one-host")


def wait_line(process: subprocess.Popen, text: str) -> None:
    line = process.stdout.readline()
    if text not in line:
        raise RuntimeError(f"expected {text!r}, got {line!r}")


def options_for(layout: str, lan: netns.Lan, port: int, secure_dir: Path):
    """(world options, agent options(host)) of a layout; starts its router if it has one."""
    endpoint = f"tcp/{lan.ip('world')}:{port}"
    if layout in ("router", "secured"):
        argv = [PY, ROUTER, "--listen", endpoint]
        if layout == "secured":
            argv = [PY, ROUTER, "--zenoh-config", str(secure_dir / "router.json5")]
        wait_line(lan.popen("world", argv, stdout=subprocess.PIPE, text=True), "listening")
        if layout == "secured":
            opts = ["--zenoh-config-dir", str(secure_dir)]
            return opts, lambda host: opts
        client = ["--mode", "client", "--connect", endpoint]
        return client, lambda host: client
    if layout == "mesh":
        return (["--mode", "peer", "--listen", endpoint],
                lambda host: ["--mode", "peer", "--listen", f"tcp/{lan.ip(host)}:0",
                              "--connect", endpoint])
    return (["--mode", "peer", "--listen", endpoint],
            lambda host: ["--mode", "client", "--connect", endpoint])


def probe_rtt(layout: str, lan: netns.Lan, port: int, secure_dir: Path) -> float | None:
    """Median get round trip host b -> host a in a layout (the world's host is the hub)."""
    if layout == "one-host":
        hub_argv = [PY, PROBE, "hub", "--mode", "peer", "--listen", f"tcp/127.0.0.1:{port}"]
        side = {h: ["--mode", "peer", "--listen", "tcp/127.0.0.1:0", "--connect",
                    f"tcp/127.0.0.1:{port}"] for h in ("a", "b")}
        hosts = {"a": "world", "b": "world"}
    else:
        endpoint = f"tcp/{lan.ip('world')}:{port}"
        hosts = {"a": "a", "b": "b"}
        if layout == "secured":
            hub_argv = [PY, ROUTER, "--zenoh-config", str(secure_dir / "router.json5")]
            side = {"a": ["--mode", "client", "--config", str(secure_dir / "agent-0.json5")],
                    "b": ["--mode", "client", "--config", str(secure_dir / "agent-1.json5")]}
        else:
            mode = {"router": "client", "mesh": "peer", "world-hub": "client"}[layout]
            hub_mode = "router" if layout == "router" else "peer"
            hub_argv = [PY, PROBE, "hub", "--mode", hub_mode, "--listen", endpoint]
            side = {h: ["--mode", mode, "--connect", endpoint] +
                    (["--listen", f"tcp/{lan.ip(h)}:0"] if mode == "peer" else []) for h in "ab"}
    hub = lan.popen("world", hub_argv, stdout=subprocess.PIPE, text=True)
    wait_line(hub, "listening" if hub_argv[1] == ROUTER else "ready")
    # In the secured layout agent 1 may ask agent 0's intent key only (access control).
    key = "nnql/bench/agent/0/intent"
    server = lan.popen(hosts["a"], [PY, PROBE, "serve", "--key", key, *side["a"]],
                       stdout=subprocess.PIPE, text=True)
    wait_line(server, "ready")
    asker = lan.popen(hosts["b"], [PY, PROBE, "ask", "--key", key, "--wanted", "2000",
                                   "--seconds", "60", *side["b"]],
                      stdout=subprocess.PIPE, text=True)
    out = asker.communicate(timeout=120)[0]
    for process in (server, hub):
        process.terminate()
        process.wait(10)
    return json.loads(out.strip().splitlines()[-1])["median_ms"]


def log(out: Path, name: str):
    out.mkdir(parents=True, exist_ok=True)
    return open(out / f"{name}.err", "w")


def swarm_rate(layout: str, lan: netns.Lan, port: int, secure_dir: Path, out: Path,
               episodes: int, agents: int) -> tuple[float, int, int, int]:
    """Ticks a second, missed intents (the first episode's, with the start-up in it; the
    others'), and episodes run of one swarm in a layout."""
    side = grid_side(agents)
    run = ["--agents", str(agents), "--grid", f"{side}x{side}", "--episodes", str(episodes),
           "--max-steps", "100", "--seed", "3", "--run-id", "bench", "--no-record", "--no-progress"]
    half = agents // 2
    if layout == "one-host":
        world = lan.popen("world", [PY, SWARM, *run, "--out", str(out / "world")],
                          stderr=log(out, "world"))
        agents = []
    else:
        world_options, agent_options = options_for(layout, lan, port, secure_dir)
        world = lan.popen("world", [PY, SWARM, *run, "--role", "world", "--out", str(out / "world"),
                                    *world_options], stderr=log(out, "world"))
        agents = [lan.popen(host, [PY, SWARM, *run, "--role", "agents", "--agent-ids", ids,
                                   "--out", str(out / host), *agent_options(host)],
                            stderr=log(out, host))
                  for host, ids in (("a", f"0-{half - 1}"), ("b", f"{half}-{agents - 1}"))]
    if world.wait(600) != 0:
        raise RuntimeError(f"{layout}: the world failed: {(out / 'world.err').read_text()[-2000:]}")
    for agent in agents:
        agent.wait(60)
    rows = read_episodes(out / "world" / "episodes.csv")
    ticks = sum(int(r["steps"]) + 1 for r in rows)
    seconds = sum(float(r["duration_s"]) for r in rows)
    missed = [int(r["missed_intents"]) for r in rows]
    return ticks / seconds, sum(missed[:1]), sum(missed[1:]), len(rows)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--layouts", default=",".join(LAYOUTS))
    p.add_argument("--agents", type=int, default=8, help="agents, split between hosts a and b")
    args = p.parse_args()
    if args.agents < 2:
        p.error("--agents must be at least 2 (one per agent host)")
    reason = netns.unavailable_reason()
    if reason:
        print(f"multihost.py: cannot make network namespaces: {reason}", file=sys.stderr)
        return 1
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(args.repeats):
            for index, layout in enumerate(args.layouts.split(",")):
                port = 7600 + index
                subnet = 100 + index  # both Lans alike: the certificate names the router's address
                with netns.Lan(["world", "a", "b"], subnet) as lan:
                    secure_dir = Path(tmp) / f"secure-{repeat}-{layout}"
                    subprocess.run([PY, SECURE, "--out", str(secure_dir), "--agents",
                                    str(args.agents),
                                    "--router-host", lan.ip("world"), "--port", str(port)],
                                   check=True, capture_output=True)
                    rtt = probe_rtt(layout, lan, port, secure_dir)
                with netns.Lan(["world", "a", "b"], subnet) as lan:
                    rate, missed_first, missed, ran = swarm_rate(layout, lan, port, secure_dir,
                                                   Path(tmp) / f"{repeat}-{layout}", args.episodes,
                                                   args.agents)
                results.setdefault(layout, []).append((rtt, rate, missed_first, missed))
                print(f"  {layout:10s} get {rtt:.3f} ms, {rate:.0f} ticks/s, missed "
                      f"{missed_first} in the first episode, {missed} after, "
                      f"{ran} of {args.episodes} episodes "
                      f"(load {os.getloadavg()[0]:.1f})", file=sys.stderr, flush=True)
    print(f"{'layout':10s} {'get_ms':>8s} {'ticks_per_s':>12s} {'missed 1st':>10s} "
          f"{'after':>6s}   "
          f"(medians of {args.repeats}, {args.agents} agents, {args.episodes} episodes of <= 100 "
          f"steps)")
    for layout, rows in results.items():
        print(f"{layout:10s} {statistics.median(r[0] for r in rows):8.3f} "
              f"{statistics.median(r[1] for r in rows):12.0f} {sum(r[2] for r in rows):10d} "
              f"{sum(r[3] for r in rows):6d}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    sys.exit(main())
