#!/usr/bin/env python3
"""How often the oracle (``world.pibt``, PIBT) brings every agent home on random maps.

Each instance is its own random map (``world.terrain``: ``random:SxS:P`` with the instance's
seed, sizes cycling over ``--sizes``) and its own starts and goals (the first episode drawn from
the same seed), played once in-process under the chosen on-target rule. Prints, per size and in
all, the instances where every agent was on its goal at the end, the mean share of agents home,
the steps over the shortest paths and the collisions (none expected).

    python -m bench.oracle_maps --agents 32 --instances 200 --seed-base 1000
    python -m bench.oracle_maps --on-target park --max-steps 128
"""

import argparse

from nnql_swarm.world import terrain as maps
from nnql_swarm.protocol.config import ON_TARGET, PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, swarm_world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=32)
    parser.add_argument("--instances", type=int, default=200)
    parser.add_argument("--seed-base", type=int, default=1000)
    parser.add_argument("--sizes", default="17,18,19,20,21", help="sides, cycled over")
    parser.add_argument("--density", type=float, default=0.2)
    parser.add_argument("--max-steps", type=int, default=256)
    parser.add_argument("--on-target", choices=ON_TARGET, default="step-aside")
    args = parser.parse_args()
    sizes = [int(s) for s in args.sizes.split(",")]
    # per size: instances, all home, share of agents home, steps, shortest, collisions
    per_size = {s: [0, 0, 0.0, 0, 0, 0] for s in sizes}
    for k in range(args.instances):
        seed = args.seed_base + k
        side = sizes[k % len(sizes)]
        rows = maps.load(f"random:{side}x{side}:{args.density}", seed)
        config = SwarmConfig(seed=seed, n_agents=args.agents, width=side, height=side,
                             max_steps=args.max_steps, map_rows=rows, on_target=args.on_target,
                             **PRESETS["oracle"])
        episodes = Batch(swarm_world(config), [config]).play(1)
        arrived = int(episodes.arrived[0, 0])
        tally = per_size[side]
        tally[0] += 1
        tally[1] += int(arrived == args.agents)
        tally[2] += arrived / args.agents
        tally[3] += int(episodes.agent_steps[0, 0])
        tally[4] += int(episodes.shortest[0, 0])
        tally[5] += int(episodes.collisions[0, 0]) + int(episodes.violations[0, 0])
    total = [sum(t[i] for t in per_size.values()) for i in range(6)]
    print(f"oracle, {args.agents} agents, random maps at {args.density} walls, "
          f"{args.max_steps} steps, on target {args.on_target}, seeds {args.seed_base}-"
          f"{args.seed_base + args.instances - 1}")
    print("| side | instances | all home | share all home | agents home | steps / shortest "
          "| collisions |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for name, t in [*((str(s), per_size[s]) for s in sizes), ("all", total)]:
        if t[0]:
            print(f"| {name} | {t[0]} | {t[1]} | {t[1] / t[0]:.3f} | {t[2] / t[0]:.3f} "
                  f"| {t[3] / max(t[4], 1):.2f} | {t[5]} |")


if __name__ == "__main__":
    main()
