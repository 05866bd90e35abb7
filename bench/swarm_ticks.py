#!/usr/bin/env python3
"""Ticks per second of the swarm: distributed and in-process, against a bare Zenoh lockstep loop.

For each agent count, in the same run and on the same machine:

- ``distributed``: ``launch/swarm.py``'s processes (world + one process per agent, embedded Zenoh);
- ``bare``: the very same processes and message pattern (observations, the negotiation of
  ``agent.negotiation``, intents) with the learning taken out: every agent answers STAY;
- ``in-process``: the same logic in one process, no Zenoh.

Each figure is the median over ``--repeats`` runs of (ticks / seconds), timed by the world from the
end of the first episode (start-up excluded). The ratio is also given as the median of each
repeat's own distributed / bare ratio: the two run back to back, so a machine whose speed drifts
between repeats disturbs it less. Rerun recording is off unless ``--record``.

    python -m bench.swarm_ticks --agents 8,16,32 --repeats 3
"""

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

from bench.harness import (
    add_preset_option, agent_sizes, run_distributed, run_local, stay_agent_main, swarm_config,
)
from nnql_swarm.launch.cli import parse_grid


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=lambda text: agent_sizes(p, text), default=[8, 16, 32],
                   help="comma-separated agent counts (default: 8,16,32)")
    p.add_argument("--episodes", type=int, default=6)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=3)
    add_preset_option(p)
    p.add_argument("--grid", type=parse_grid, default=(11, 11),
                   help="WIDTHxHEIGHT (default: 11x11, widened where the agents need more)")
    p.add_argument("--record", action="store_true", help="also write run.rrd (Rerun cost included)")
    args = p.parse_args()
    print(f"{'agents':>6} {'mode':>12} {'ticks/s':>9} {'ms/tick':>8}  runs")
    width, height = args.grid
    for n in args.agents:
        config = swarm_config(args.preset, run_id=f"bench{n}", n_agents=n, episodes=args.episodes,
                              max_steps=args.max_steps, width=max(width, 2 * n // height + 1),
                              height=height)
        results = {}
        with tempfile.TemporaryDirectory() as tmp:
            for r in range(args.repeats):
                for mode in ("distributed", "bare", "in-process"):
                    out = Path(tmp) / f"{mode}-{r}"
                    if mode == "in-process":
                        rate = run_local(config, out, args.record)
                    else:
                        rate = run_distributed(config, out, args.record,
                                               stay_agent_main if mode == "bare" else None)
                    results.setdefault(mode, []).append(rate)
        for mode, rates in results.items():
            median = statistics.median(rates)
            runs = " ".join(f"{x:.0f}" for x in rates)
            print(f"{n:>6} {mode:>12} {median:>9.0f} {1000 / median:>8.2f}  {runs}", flush=True)
        ratio = statistics.median(results["distributed"]) / statistics.median(results["bare"])
        paired = statistics.median(d / b for d, b in zip(results["distributed"], results["bare"]))
        print(f"{n:>6} {'ratio':>12} {ratio:>9.2f}  distributed / bare (medians); "
              f"{paired:.2f} median of each repeat's own ratio", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
