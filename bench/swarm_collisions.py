#!/usr/bin/env python3
"""nnQL (and its direction-aware variant) against QL in the swarm (every agent learns, each its own goal): collisions and steps.

Runs the in-process swarm (the same logic as the distributed one, see tests/test_swarm.py's
parity test) for both algorithms over the same seeds and reports, per algorithm, the mean over
seeds of total collisions, collisions per episode in the last 20 % of episodes, and steps per
episode against the shortest possible, with the paired difference and its 95 % interval.

    python bench/swarm_collisions.py --agents 8 --episodes 200 --seeds 5
"""

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from launch.inprocess import run_in_process  # noqa: E402
from experiment.stats import mean_interval  # noqa: E402
from protocol.config import SwarmConfig  # noqa: E402
from world.metrics import read_episodes  # noqa: E402


def run(algo: str, seed: int, args) -> dict:
    config = SwarmConfig(run_id=f"{algo}-{seed}", n_agents=args.agents, episodes=args.episodes,
                         max_steps=args.max_steps, seed=seed, algo=algo,
                         count_swaps=not args.no_swaps)
    with tempfile.TemporaryDirectory() as tmp:
        run_in_process(config, Path(tmp), checkpoints=False)
        rows = read_episodes(Path(tmp) / "episodes.csv")
    tail = rows[-max(1, len(rows) // 5):]
    return {
        "collisions": sum(int(r["collisions"]) for r in rows),
        "late_collisions": statistics.mean(int(r["collisions"]) for r in tail),
        "steps_ratio": sum(int(r["agent_steps"]) for r in tail) / sum(int(r["shortest_sum"]) for r in tail),
        "arrived": statistics.mean(int(r["arrived"]) for r in tail),
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=200)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--no-swaps", action="store_true", help="do not count swaps as collisions")
    p.add_argument("--algos", default="ql,nnql", help="the first is the baseline")
    args = p.parse_args()
    algos = args.algos.split(",")
    results = {algo: [run(algo, s, args) for s in range(args.seeds)] for algo in algos}
    print(f"{args.agents} agents, {args.episodes} episodes, {args.seeds} seeds, "
          f"swaps {'not ' if args.no_swaps else ''}counted")
    for key in ("collisions", "late_collisions", "steps_ratio", "arrived"):
        line = [key.ljust(16)]
        for algo in algos:
            i = mean_interval([r[key] for r in results[algo]])
            line.append(f"{algo} {i.mean:9.2f} [{i.low:.2f}, {i.high:.2f}]")
        print("  ".join(line))
    base = algos[0]
    base_mean = statistics.mean(r["collisions"] for r in results[base])
    for algo in algos[1:]:
        diff = [b["collisions"] - o["collisions"] for b, o in zip(results[base], results[algo])]
        i = mean_interval(diff)
        print(f"{base} - {algo} total collisions: {i.mean:.1f} [{i.low:.1f}, {i.high:.1f}]  "
              f"({100 * i.mean / base_mean:.1f} % fewer with {algo})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
