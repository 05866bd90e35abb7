#!/usr/bin/env python3
"""Messages a tick, by kind, and the critical path of a tick, of the distributed swarm's
protocol on the simulated network: exact and repeatable where ticks a second on a shared machine
are not.

Runs the world's and the agents' protocol machines (``sim.distributed``, no faults, each message
100 to 300 us on its way) and counts what each process sends (``sim.network.Network.sent_by``):
observations, intents, answers, queries and their ends. ``virtual ms a tick`` is the run's
virtual time over its ticks: the chain of messages a tick waits for, without the CPU that each
costs for real. Another tree's protocol runs with that tree's package first on ``PYTHONPATH``
(as ``bench/paired.py`` builds it).

    python -m bench.negotiation_messages --agents 64 --episodes 10 --max-steps 60
    python -m bench.negotiation_messages --agents 8 --episodes 6 --max-steps 100
"""

import argparse
import sys

from bench.harness import add_preset_option, grid_side, swarm_config

LATENCY_S = (100e-6, 300e-6)
"""The simulated network's latency range, each message drawn from it."""


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=64)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--max-steps", type=int, default=60)
    p.add_argument("--seed", type=int, default=0)
    add_preset_option(p)
    args = p.parse_args()
    if args.agents < 2 or args.episodes < 1 or args.max_steps < 1:
        p.error("need at least 2 agents, 1 episode and 1 step")
    from nnql_swarm.sim.distributed import SimSwarm
    from nnql_swarm.sim.schedule import Schedule

    side = grid_side(args.agents)
    config = swarm_config(args.preset, n_agents=args.agents, width=side, height=side,
                          episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
                          run_id="messages")
    swarm = SimSwarm(Schedule(args.seed, config, LATENCY_S, ()))
    outcome = swarm.run()
    if outcome.failures:
        print("the run failed its checks: " + "; ".join(outcome.failures[:3]), file=sys.stderr)
        return 1
    ticks = outcome.ticks
    print(f"{args.agents} agents on {side} x {side}, preset {args.preset}, "
          f"{args.episodes} episodes of at most {args.max_steps} steps: {ticks} ticks, virtual ms a tick "
          f"{1000 * outcome.virtual_s / ticks:.3f}")
    print("| message (what its arrival calls) | sent | a tick |")
    print("| --- | ---: | ---: |")
    sent = swarm.net.sent_by
    for kind, count in sent.most_common():
        print(f"| {kind} | {count:,} | {count / ticks:.2f} |")
    total = sum(sent.values())
    print(f"| all | {total:,} | {total / ticks:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
