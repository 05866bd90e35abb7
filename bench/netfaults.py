#!/usr/bin/env python3
"""What each fault on the real network costs: a swarm through a router across namespace hosts.

tests/netfault_runs.py's layout (the router and the world on host ``world``, half the agents on
host ``a``, half on ``b``, each process a client of the router) runs once per fault and repeat,
and prints per fault: the median ticks a second (all ticks over all episodes' durations, as
bench/multihost.py) and its ratio to the clean run's, the median seconds the fault added to the
run's ticking (its episodes' durations against the clean run's: what a fault that passes costs,
whatever the run's length), the missed intents of each repeat, whether every episode was
written once, and how many of the repeats without a missed intent have the rows of
``--in-process``. Faults the machine
cannot make (no netem in the kernel, no iptables) are listed with the reason. Needs root.

    sudo .venv/bin/python -m bench.netfaults --repeats 3
    sudo .venv/bin/python -m bench.netfaults --faults clean,partition-long --repeats 1
    sudo .venv/bin/python -m bench.netfaults --faults clean,router-restart \
        --zenoh-config config/client.json5     # every process with the file's settings
"""

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
from tests import netfault_runs as runs
from tests import netns
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes


def in_process(out: Path, agents: int, episodes: int, max_steps: int, seed: int) -> list[tuple]:
    subprocess.run([sys.executable, str(runs.SWARM), "--agents", str(agents), "--episodes",
                    str(episodes), "--max-steps", str(max_steps), "--seed", str(seed),
                    "--in-process", "--no-record", "--no-progress", "--out", str(out)],
                   check=True, capture_output=True, cwd=ROOT)
    return [tuple(r[f] for f in EPISODE_FIELDS) for r in read_episodes(out / "episodes.csv")]


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--faults", default=",".join(runs.DEFAULT_FAULTS),
                   help=f"of {', '.join(runs.FAULTS)}")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--agents", type=int, default=4, help="agents, split between hosts a and b")
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--max-steps", type=int, default=30)
    p.add_argument("--seed", type=int, default=3)
    p.add_argument("--zenoh-config", default=None, metavar="FILE",
                   help="a client config for the world and the agents (--connect still given)")
    args = p.parse_args()
    options = ("--zenoh-config", str(Path(args.zenoh_config).resolve())) if args.zenoh_config \
        else ()
    faults = [runs.FAULTS[name] for name in args.faults.split(",") if name]
    reason = netns.unavailable_reason()
    if reason:
        print(f"netfaults.py: cannot make network namespaces: {reason}", file=sys.stderr)
        return 1
    size = dict(agents=args.agents, episodes=args.episodes, max_steps=args.max_steps,
                seed=args.seed)
    results: dict[str, list[runs.Outcome]] = {}
    skipped: dict[str, str] = {}
    with tempfile.TemporaryDirectory() as tmp:
        reference = in_process(Path(tmp) / "in-process", **size)
        for repeat in range(args.repeats):
            for index, fault in enumerate(faults):
                why = runs.unavailable(fault)
                if why is not None:
                    skipped[fault.name] = why
                    continue
                with netns.Lan(runs.HOSTS) as lan:
                    outcome = runs.run(lan, Path(tmp) / f"{repeat}-{fault.name}", fault,
                                       port=7800 + index, run_options=options, **size)
                results.setdefault(fault.name, []).append(outcome)
                late = f" (timed out: {', '.join(outcome.timed_out)})" if outcome.timed_out else ""
                print(f"  {fault.name:20s} {outcome.ticks_per_s:6.1f} ticks/s, missed "
                      f"{outcome.missed}, exit codes {outcome.world_code} {outcome.agent_codes}"
                      f"{late}, "
                      f"{len(outcome.rows)} of {args.episodes} episodes, "
                      f"{outcome.wall_s:.1f} s (load {os.getloadavg()[0]:.1f})",
                      file=sys.stderr, flush=True)
    clean = results.get("clean")
    base = statistics.median(o.ticks_per_s for o in clean) if clean else None
    def ticking(outcome: runs.Outcome) -> float:
        return sum(float(row["duration_s"]) for row in outcome.rows)

    base_s = statistics.median(ticking(o) for o in clean) if clean else None
    print(f"{'fault':20s} {'ticks_per_s':>11s} {'vs_clean':>8s} {'added_s':>7s} {'missed':>12s} "
          f"{'complete':>8s} {'=in-process':>11s}   (medians of {args.repeats}; {args.agents} "
          f"agents, {args.episodes} episodes of <= {args.max_steps} steps, seed {args.seed})")
    for name, outcomes in results.items():
        rate = statistics.median(o.ticks_per_s for o in outcomes)
        complete = all(o.complete(args.episodes) for o in outcomes)
        clean_runs = [o for o in outcomes if o.missed == 0]
        equal = (f"{sum(o.deterministic() == reference for o in clean_runs)}/{len(clean_runs)}"
                 if clean_runs else "-")
        missed = ",".join(str(o.missed) for o in outcomes)
        ratio = f"{rate / base:.2f}" if base else "-"
        added = f"{statistics.median(ticking(o) for o in outcomes) - base_s:.1f}" if base else "-"
        print(f"{name:20s} {rate:11.1f} {ratio:>8s} {added:>7s} {missed:>12s} "
              f"{'yes' if complete else 'NO':>8s} {equal:>11s}")
    for name, why in skipped.items():
        print(f"{name:20s} not run: {why}")
    print(f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    return 0


if __name__ == "__main__":
    sys.exit(main())
