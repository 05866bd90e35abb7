#!/usr/bin/env python3
"""Soak run (not in CI): a swarm under random faults for a while; nothing may be lost.

Faults, drawn from a seeded generator every ``--every`` seconds: ``kill -9`` an agent (the
launcher restarts it from its checkpoint), ``SIGSTOP`` an agent for a few seconds then
``SIGCONT``, ``kill -9`` the world (the soak resumes the run with ``--resume``). At the end it
reports ticks, faults injected and survived, episodes lost (missing or duplicated rows, must be
0), learned values lost (agents whose tables went back to zero, must be 0) and the memory
growth (RSS) of each process role.

    python -m bench.soak --minutes 10 --agents 8
"""

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
import numpy as np

from nnql_swarm.agent import agent_checkpoint
from tests.swarm_helpers import find_process, group_pids, swarm_command
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.world.metrics import read_episodes


WARM_UP_S = 20.0
"""Memory is compared from this long after a process started (imports and first episodes done)."""


def rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def start(out: Path, options: list[str], log) -> subprocess.Popen:
    return subprocess.Popen(swarm_command(out, *options), cwd=ROOT, stdout=log, stderr=log,
                            start_new_session=True)


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--every", type=float, default=15.0, help="seconds between faults")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    rng = random.Random(args.seed)
    run_id = "soak"
    tmp = Path(tempfile.mkdtemp(prefix="nnql-soak-"))
    out = tmp / "run"
    log = open(tmp / "swarm.log", "w")
    options = ["--agents", str(args.agents), "--episodes", "1000000", "--run-id", run_id,
               "--deadline", "0.5", "--no-record"]
    swarm = start(out, options, log)
    faults = {"agent-kill": 0, "agent-stall": 0, "world-kill": 0}
    memory: dict[tuple[str, int], list[tuple[float, int]]] = {}
    end = time.monotonic() + args.minutes * 60
    next_fault = time.monotonic() + args.every
    try:
        while time.monotonic() < end:
            time.sleep(1.0)
            for role in ["nnql-world"] + [f"nnql-agent {i}" for i in range(args.agents)]:
                for pid in find_process(f"{role} {run_id}"):
                    memory.setdefault((role, pid), []).append((time.monotonic(), rss_kib(pid)))
            if swarm.poll() is not None and faults["world-kill"] == 0 and swarm.returncode != 0:
                raise SystemExit(f"the swarm died unexpectedly ({swarm.returncode}); see {tmp}")
            if time.monotonic() < next_fault:
                continue
            next_fault = time.monotonic() + args.every
            fault = rng.choice(list(faults))
            if fault == "world-kill":
                for pid in find_process(f"nnql-world {run_id}"):
                    os.kill(pid, signal.SIGKILL)
                swarm.wait(timeout=30)
                swarm = start(out, ["--resume", "--no-record"], log)
            else:
                victims = find_process(f"nnql-agent {rng.randrange(args.agents)} {run_id}")
                if not victims:
                    continue
                if fault == "agent-kill":
                    os.kill(victims[0], signal.SIGKILL)
                else:
                    os.kill(victims[0], signal.SIGSTOP)
                    time.sleep(rng.uniform(1.0, 4.0))
                    os.kill(victims[0], signal.SIGCONT)
            faults[fault] += 1
            print(f"{time.strftime('%H:%M:%S')} injected {fault}", flush=True)
    finally:
        os.killpg(swarm.pid, signal.SIGINT)
        swarm.wait(timeout=30)
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    rows = read_episodes(out / "episodes.csv")
    episodes = [int(r["episode"]) for r in rows]
    lost = len(set(range(max(episodes) + 1)) - set(episodes)) + (len(episodes) - len(set(episodes)))
    zeroed = 0
    for agent in range(args.agents):
        data = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), ())
        zeroed += int(np.abs(data["q_ds"]).sum() == 0 or np.abs(data["q_ca"]).sum() == 0)
    ticks = int(rows[-1]["end_tick"]) + 1
    print(f"\nsoak: {args.minutes:g} min, {args.agents} agents, {ticks} ticks, {len(rows)} episodes")
    print(f"faults injected and survived: {faults} (the run went on after each)")
    print(f"episodes lost or duplicated: {lost}")
    print(f"agents whose learned values were lost: {zeroed}")
    print(f"missed intents: {sum(int(r['missed_intents']) for r in rows)}, "
          f"slowest tick {max(float(r['max_tick_ms']) for r in rows):.0f} ms")
    print(f"memory (RSS) of each role's longest-lived process, {WARM_UP_S:.0f} s after it started "
          f"and at its last sample:")
    for role in sorted({role for role, _ in memory}):
        samples = max((v for (r, _), v in memory.items() if r == role), key=len)
        warm = [rss for t, rss in samples if t - samples[0][0] >= WARM_UP_S]
        if len(warm) >= 2:
            lived = samples[-1][0] - samples[0][0]
            print(f"  {role:>14}: {warm[0] / 1024:.1f} MiB -> {warm[-1] / 1024:.1f} MiB "
                  f"over {lived:.0f} s ({(warm[-1] - warm[0]) / 1024:+.1f} MiB)")
    print(f"run directory: {out}")
    return 0 if lost == 0 and zeroed == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
