#!/usr/bin/env python3
"""The swarm against its number of agents, at constant density, beside the bare lockstep loop.

For each size (8, 16, 32, 64, 128 agents on 11 x 11, 16 x 16, 22 x 22, 32 x 32 and 45 x 45: about
one agent per 16 cells), in the same run and interleaved repeat by repeat:

- the distributed swarm (the launcher's world and agent processes, embedded Zenoh, recording
  off, the default preset unless ``--preset``): ticks a second over every episode but the first
  (``bench.harness.measured_rate``), missed intents in the first episode and after it, the
  start-up (from starting the processes until the world saw every agent's liveliness token and
  opened the first tick, from its stats file) and the peak
  resident memory of the world and of the largest agent;
- the bare loop of ``bench/lockstep.py`` with as many agents: every agent answers at once, no
  negotiation, no learning, the floor under a tick;
- with ``--split``, also the swarm with the learning taken out (``bench.harness.stay_agent_main``:
  every agent observes, negotiates and answers as the learner does, then stays), which splits
  the gap to the bare loop into what the protocol costs (its messages, its chains of answers,
  the codec, the world's rules and checks) and what the learning adds. Its agents never arrive,
  so each of its episodes runs to ``--max-steps``;
- with ``--pattern``, also the swarm's own messages with no work in them (``bench/pattern.py``:
  the same run's messages, tick by tick, replayed by bare processes): the most the swarm could
  reach were our Python free.

``--obstacle-density P`` puts walls on the swarm's grids (``protocol.walls``), the same grids.

Prints one row per size (medians over the repeats; each repeat's figures on stderr), the cost
of a tick per agent (ms a tick / N: flat where cost grows linearly) and, with ``--png``, draws
ticks a second and milliseconds a tick per agent against N for both.

    python -m bench.scale --agents 8,16,32,64 --repeats 3 --png docs/scale.png
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

# The rest is imported where it is used: the swarm's processes fork from a server that imported
# this module (``launch.processes.main_to_serve``), so what it imports at the top would be in
# every agent, and an agent's memory is one of the figures measured.

def swarm_once(n: int, preset: str, episodes: int, max_steps: int, seed: int,
               topology: str, obstacle_density: float = 0.0, agent_target=None) -> dict:
    import tempfile

    from bench.harness import grid_side, measured_ticks, run_distributed, swarm_config
    from bench.procstat import MemorySampler
    from nnql_swarm.transport.runfiles import stats_path
    from nnql_swarm.transport.topology import EmbeddedLayout
    from nnql_swarm.world.metrics import read_episodes

    side = grid_side(n)
    config = swarm_config(preset, n_agents=n, width=side, height=side, episodes=episodes,
                          max_steps=max_steps, seed=seed, run_id=f"scale-{n}",
                          obstacle_density=obstacle_density)
    with tempfile.TemporaryDirectory() as tmp, MemorySampler() as memory:
        out = Path(tmp) / "run"
        launched = time.time()  # the processes start within milliseconds of it
        rate = run_distributed(config, out, record=False, memory=memory,
                               layout=EmbeddedLayout(topology=topology), agent_target=agent_target)
        rows = read_episodes(out / "episodes.csv")
        world = json.loads(stats_path(out, "world").read_text())
        startup = world["started_at"] - launched
        ticks, began, ended = measured_ticks(out)
        peaks = memory.peaks()
    agents = [mib for name, mib in peaks.items() if name.startswith("agent")]
    return {"rate": rate, "missed": sum(int(r["missed_intents"]) for r in rows[1:]),
            "missed_first": int(rows[0]["missed_intents"]),
            "startup_s": startup, "measured_ticks": ticks,
            "window": (world["started_at"] + began, world["started_at"] + ended),
            "world_mib": peaks.get("world", math.nan), "agent_mib": max(agents, default=math.nan),
            "arrived": sum(int(r["arrived"]) for r in rows[1:]) / max(n * (len(rows) - 1), 1)}


def bare_once(n: int, ticks: int, topology: str) -> dict:
    from bench import lockstep

    result = lockstep.run(n, topology, ticks)
    return {"rate": result["rate"], "startup_s": result["startup_s"], "cpu_us": result["cpu_us"]}


def pattern_once(pattern, ticks: int, topology: str) -> dict:
    from bench.pattern import replay

    return replay(pattern, topology, ticks)


def median(runs: list[dict], key: str) -> float:
    import statistics

    values = [r[key] for r in runs if r[key] is not None and not math.isnan(r[key])]
    return statistics.median(values) if values else math.nan


def main() -> int:
    import statistics

    from bench.harness import (
        add_preset_option, agent_sizes, grid_side, stay_agent_main, swarm_config,
    )
    from nnql_swarm.transport.topology import TOPOLOGIES, embedded_topology

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", default="8,16,32,64,128", help="comma-separated agent counts")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--episodes", type=int, default=6, help="swarm episodes per run (the first "
                   "is start-up and not timed)")
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--bare-ticks", type=int, default=2000, help="ticks of each bare loop")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--png", type=Path, default=None, help="draw the curves into this PNG")
    p.add_argument("--topology", choices=("auto", *TOPOLOGIES), default="auto",
                   help="how the processes connect, swarm and bare loop alike (default: auto, "
                        "the launcher's choice for each size)")
    p.add_argument("--obstacle-density", type=float, default=0.0, metavar="P",
                   help="walls on the swarm's grid (the bare loop has none)")
    p.add_argument("--split", action="store_true",
                   help="also run the swarm with the learning taken out (agents negotiate, then "
                        "stay): what the protocol costs apart from the learning")
    p.add_argument("--pattern", action="store_true",
                   help="also replay the swarm's own messages with no work in them "
                        "(bench/pattern.py): the most the swarm could reach were our Python free")
    add_preset_option(p)
    args = p.parse_args()
    sizes = agent_sizes(p, args.agents)
    if args.repeats < 1 or args.episodes < 2:
        p.error("need --repeats >= 1 and --episodes >= 2")
    for n in sizes:
        try:
            swarm_config(args.preset, n_agents=n, width=grid_side(n), height=grid_side(n),
                         obstacle_density=args.obstacle_density)
        except ValueError as error:
            p.error(f"{n} agents: {error}")

    table = []
    for n in sizes:
        swarm, bare, staying, replays = [], [], [], []
        topology = embedded_topology(n) if args.topology == "auto" else args.topology
        pattern = None
        if args.pattern:
            from bench.pattern import record

            side = grid_side(n)
            pattern = record(swarm_config(
                args.preset, run_id=f"scale-{n}", n_agents=n, width=side, height=side,
                episodes=args.episodes, max_steps=args.max_steps, seed=args.seed,
                obstacle_density=args.obstacle_density))
        for repeat in range(args.repeats):
            swarm.append(swarm_once(n, args.preset, args.episodes, args.max_steps, args.seed,
                                    topology, args.obstacle_density))
            bare.append(bare_once(n, args.bare_ticks, topology))
            if args.split:
                staying.append(swarm_once(n, args.preset, args.episodes, args.max_steps,
                                          args.seed, topology, args.obstacle_density,
                                          agent_target=stay_agent_main))
            if pattern is not None:
                replays.append(pattern_once(pattern, args.bare_ticks, topology))
            s, b = swarm[-1], bare[-1]
            split = f", learning nothing {staying[-1]['rate']:.0f} ticks/s" if staying else ""
            split += f", its messages alone {replays[-1]['rate']:.0f} ticks/s" if replays else ""
            print(f"  {n} agents, repeat {repeat + 1}: swarm {s['rate']:.0f} ticks/s "
                  f"(missed {s['missed_first']} then {s['missed']}, start-up "
                  f"{s['startup_s']:.1f} s, agent {s['agent_mib']:.1f} MiB), bare "
                  f"{b['rate']:.0f} ticks/s{split}", file=sys.stderr, flush=True)
        ratios = [s["rate"] / b["rate"] for s, b in zip(swarm, bare)]
        row = {"agents": n, "grid": grid_side(n), "topology": topology, "swarm": median(swarm, "rate"),
               "bare": median(bare, "rate"), "ratio": statistics.median(ratios),
               "missed": median(swarm, "missed"), "missed_first": median(swarm, "missed_first"),
               "startup_s": median(swarm, "startup_s"), "agent_mib": median(swarm, "agent_mib"),
               "world_mib": median(swarm, "world_mib"), "arrived": median(swarm, "arrived"),
               "runs": [round(s["rate"]) for s in swarm], "bare_runs": [round(b["rate"]) for b in bare]}
        if staying:
            row["staying"] = median(staying, "rate")
            row["staying_ratio"] = statistics.median(
                t["rate"] / b["rate"] for t, b in zip(staying, bare))
            row["staying_runs"] = [round(t["rate"]) for t in staying]
        if replays:
            row["pattern"] = median(replays, "rate")
            row["pattern_ratio"] = statistics.median(
                t["rate"] / b["rate"] for t, b in zip(replays, bare))
            row["pattern_runs"] = [t["rate"] if math.isnan(t["rate"]) else round(t["rate"])
                                   for t in replays]  # nan: a replay that never started
        row["ms_per_agent"] = 1000.0 / row["swarm"] / n
        row["bare_ms_per_agent"] = 1000.0 / row["bare"] / n
        table.append(row)
    print_table(table, args)
    if args.png is not None:
        draw(table, args.png)
        args.png.with_suffix(".json").write_text(json.dumps(table, indent=1) + "\n")
        print(f"curves: {args.png} (their figures: {args.png.with_suffix('.json')})")
    return 0


def print_table(table: list[dict], args) -> None:
    print(f"preset {args.preset}, topology {args.topology}, {args.episodes} episodes of at most {args.max_steps} steps, "
          f"medians of {args.repeats}")
    print("| agents | grid | topology | swarm ticks/s | bare ticks/s | ratio | ms a tick per agent "
          "(swarm / bare) | missed intents (1st episode / after) | start-up s | agent MiB | "
          "world MiB | runs (swarm; bare) |")
    print("| ---: | ---: | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | --- |")
    for r in table:
        print(f"| {r['agents']} | {r['grid']}x{r['grid']} | {r['topology']} | {r['swarm']:.0f} | {r['bare']:.0f} | "
              f"{r['ratio']:.2f} | {r['ms_per_agent']:.3f} / {r['bare_ms_per_agent']:.3f} | "
              f"{r['missed_first']:.0f} / {r['missed']:.0f} | {r['startup_s']:.1f} | "
              f"{r['agent_mib']:.1f} | {r['world_mib']:.0f} | "
              f"{' '.join(map(str, r['runs']))}; {' '.join(map(str, r['bare_runs']))} |")
    beside(table, "staying", "the swarm with the learning taken out (agents negotiate, then "
           "stay)", "learning nothing, ticks/s | its ratio")
    beside(table, "pattern", "the swarm's own messages with no work in them (bench/pattern.py)",
           "its messages alone, ticks/s | their ratio")


def beside(table: list[dict], key: str, what: str, columns: str) -> None:
    """The table of a swarm run beside the swarm (``--split``: ``staying``, ``--pattern``:
    ``pattern``), where the rows have it."""
    rows = [r for r in table if key in r]
    if not rows:
        return
    print(f"\n{what}, in the same runs; ratios to the bare loop, each repeat's own, medians")
    print(f"| agents | {columns} | the swarm's ratio | runs |")
    print("| ---: | ---: | ---: | ---: | --- |")
    for r in rows:
        print(f"| {r['agents']} | {r[key]:.0f} | {r[key + '_ratio']:.2f} | {r['ratio']:.2f} | "
              f"{' '.join(map(str, r[key + '_runs']))} |")


def draw(table: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["agents"] for r in table]
    fig, (rate, cost) = plt.subplots(1, 2, figsize=(11, 4.2))
    rate.plot(n, [r["swarm"] for r in table], "o-", label="swarm (negotiation, learning)")
    rate.plot(n, [r["bare"] for r in table], "s--", label="bare loop (all answer at once)")
    if all("pattern" in r for r in table):
        rate.plot(n, [r["pattern"] for r in table], "^:",
                  label="the swarm's messages, no work (--pattern)")
    rate.set(xscale="log", yscale="log", xlabel="agents", ylabel="ticks a second",
             title="Ticks a second, constant density")
    cost.plot(n, [r["ms_per_agent"] for r in table], "o-", label="swarm")
    cost.plot(n, [r["bare_ms_per_agent"] for r in table], "s--", label="bare loop")
    if all("pattern" in r for r in table):
        cost.plot(n, [1000.0 / r["pattern"] / r["agents"] for r in table], "^:",
                  label="the swarm's messages, no work")
    cost.set(xscale="log", xlabel="agents", ylabel="ms a tick / agents",
             title="Cost of a tick per agent (flat = linear)")
    for axis in (rate, cost):
        axis.minorticks_off()
        axis.set_xticks(n, [str(v) for v in n])
        axis.grid(True, alpha=0.3)
        axis.legend()
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
