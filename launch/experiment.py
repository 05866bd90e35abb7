"""The experiments as a command line: the paper's comparison of QL and nnQL (Section 4: Table 1,
Figs. 5-13; the default), and the swarm experiment over the learning presets.

    python launch/experiment.py                      # the paper's settings, 10 seeds, k = 1..10
    python launch/experiment.py --episodes 50 --seeds 3 --ks 1,5 --out runs/quick
    python launch/experiment.py paper ...            # the same, by name
    python launch/experiment.py swarm --agents 8 --seeds 10 --episodes 500 --out runs/swarm
    python launch/experiment.py maps --out runs/maps    # the field's benchmark (POGEMA's protocol)

The paper's writes ``table1.csv``, ``table1.md``, ``episodes.csv``, ``config.json`` and the
figures into ``--out``; the swarm's ``swarm_table.csv``, ``swarm_table.md``, ``config.json``,
``runs/<variant>-s<seed>/`` (each run's ``config.json`` and ``episodes.csv``), the learning curves
(``swarm_*.png``) and their Rerun recording ``swarm_curves.rrd``; the maps benchmark's
``maps_table.csv``, ``maps_table.md``, ``maps_episodes.csv`` (every episode, written as it is
played), ``maps_curves.csv`` and ``maps_curves.rrd`` (the learning curves), ``policies/`` (each
seed's learned tables) and ``config.json``.
"""

import argparse
import json
import os
import signal
import sys
import time
from dataclasses import asdict
from pathlib import Path

from nnql_swarm.experiment.paper import (
    ALGOS, PaperSettings, RunSpec, paper_run, paper_world, run_batch,
)
from nnql_swarm.experiment.report import (
    ResultGrid, summarize, table1_markdown, table1_rows, write_episodes_csv, write_table1_csv,
)
from nnql_swarm.experiment.swarm_experiment import (
    TABLE_FILES, VARIANTS, SwarmExperiment, ablation_presets, curves, run_experiment, table_rows,
    walls_presets, write_runs, write_tables,
)
from nnql_swarm.protocol.config import ON_TARGET, PRESETS
from nnql_swarm.world.terrain import run_map
from nnql_swarm.sim.runs import swarm_world
from nnql_swarm.launch.experiment_maps import run_maps
from nnql_swarm.launch.cli import (
    DefaultsHelpFormatter, EXIT_INTERRUPTED, OneLineParser, Terminated, bounded, comma_choices,
    parse_grid, parse_workers, prepare_simulator, program_name, progress,
    raise_terminated, report_written, results_folder,
)
from nnql_swarm.recording.curves import log_swarm_curves

RESULT_FILES = ("table1.csv", "table1.md", "episodes.csv", "config.json")

EXIT_TERMINATED = 143
DEFAULTS = PaperSettings()


def parse_ks(text: str) -> list[int]:
    """``"1-10"``, ``"1,2,5"`` or ``"1-3,7"`` -> sorted distinct random steps, each at least 1."""
    ks: set[int] = set()
    for part in text.split(","):
        part = part.strip()
        try:
            if "-" in part:
                first, last = (int(p) for p in part.split("-", 1))
                if first > last:
                    raise ValueError
                ks.update(range(first, last + 1))
            else:
                ks.add(int(part))
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a list or range of integers: {text!r}") from None
    if min(ks) < 1:
        raise argparse.ArgumentTypeError(f"every random step k must be at least 1: {text!r}")
    return sorted(ks)


def build_parser() -> OneLineParser:
    parser = OneLineParser(
        description="QL vs nnQL, the paper's experiment: one learner among scripted obstacles "
        "that announce their next action. The paper's settings are the defaults. (The swarm "
        "experiment: %(prog)s swarm --help.)",
    )
    add = parser.add_argument
    add("--seeds", type=bounded(int, 1), default=10, metavar="N",
        help="independent runs per (algo, k) (default 10)")
    add("--seed-base", type=bounded(int, 0), default=0, metavar="S",
        help="first seed; seeds are S, S+1, ... (default 0)")
    add("--episodes", type=bounded(int, 1), default=DEFAULTS.episodes, metavar="N",
        help=f"episodes per run (default {DEFAULTS.episodes})")
    add("--max-steps", type=bounded(int, 1), default=DEFAULTS.max_steps, metavar="N",
        help=f"steps per episode at most (default {DEFAULTS.max_steps})")
    add("--ks", type=parse_ks, default=list(range(1, 11)), metavar="KS",
        help="random steps k: every k-th action is random; a range or list (default 1-10)")
    add("--algos", type=comma_choices(ALGOS, "algorithms", fold_case=True), default=ALGOS,
        help="algorithms to compare (default ql,nnql)")
    add("--alpha", type=bounded(float, 0.0, 1.0), default=DEFAULTS.alpha,
        help=f"learning rate (default {DEFAULTS.alpha})")
    add("--gamma", type=bounded(float, 0.0, 1.0), default=DEFAULTS.gamma,
        help=f"discount factor (default {DEFAULTS.gamma})")
    add("--beta", type=bounded(float, 0.0, 1.0), default=DEFAULTS.beta,
        help=f"weight of destination seeking in Eq. 7 (default {DEFAULTS.beta})")
    add("--goal-reward", type=bounded(float, 0.0), default=DEFAULTS.goal_reward,
        help=f"destination-seeking reward on arriving (default {DEFAULTS.goal_reward:g})")
    add("--obstacles", type=bounded(int, 0), default=DEFAULTS.n_obstacles, metavar="N",
        help=f"scripted obstacles (default {DEFAULTS.n_obstacles}, calibrated on Table 1's k = 1 row)")
    add("--grid", type=parse_grid, default=(DEFAULTS.width, DEFAULTS.height), metavar="WxH",
        help=f"grid size (default {DEFAULTS.width}x{DEFAULTS.height})")
    add("--count-swaps", action="store_true",
        help="count two agents swapping cells as a collision (the paper does not)")
    add("--out", type=Path, default=None, metavar="DIR",
        help="output directory (default runs/experiment-<time>)")
    add("--force", action="store_true", help="overwrite results already in --out")
    add("--figure-k", type=bounded(int, 1), default=None, metavar="K",
        help="random step k of the per-episode figures (default: the largest k run)")
    add("--no-plots", action="store_true", help="skip the figures (no matplotlib needed)")
    add("--workers", type=parse_workers, default=None, metavar="N|auto",
        help="threads the runs are spread over (default auto: one per core)")
    return parser


def resolve(args: argparse.Namespace, parser: OneLineParser) -> argparse.Namespace:
    """Cross-option checks and defaults that depend on other options."""
    width, height = args.grid
    if width * height < args.obstacles + 2:
        parser.error(
            f"a {width}x{height} grid has {width * height} cells; {args.obstacles} obstacles, "
            f"the learner and its goal need {args.obstacles + 2}"
        )
    if args.figure_k is None:
        args.figure_k = max(args.ks)
    elif args.figure_k not in args.ks:
        parser.error(f"--figure-k {args.figure_k} is not among the random steps run ({args.ks})")
    args.out = results_folder(parser, args.out, "experiment", RESULT_FILES, args.force,
                              plots=not args.no_plots)
    if args.workers is None:
        args.workers = os.cpu_count() or 1
    return args


def settings_from(args: argparse.Namespace) -> PaperSettings:
    return PaperSettings(
        episodes=args.episodes,
        max_steps=args.max_steps,
        width=args.grid[0],
        height=args.grid[1],
        n_obstacles=args.obstacles,
        count_swaps=args.count_swaps,
        goal_reward=args.goal_reward,
        alpha=args.alpha, gamma=args.gamma, beta=args.beta,
    )


def run(args: argparse.Namespace) -> Path:
    """Run the experiment and write every result file; returns the output directory."""
    settings = settings_from(args)
    seeds = list(range(args.seed_base, args.seed_base + args.seeds))
    specs = [RunSpec(algo, k, seed) for algo in args.algos for k in args.ks for seed in seeds]
    args.out.mkdir(parents=True, exist_ok=True)
    prepare_simulator(paper_world(settings), paper_run(specs[0], settings))
    started = time.monotonic()
    label = f"{len(specs)} runs x {settings.episodes} episodes"
    with progress(len(specs) * settings.episodes, "run-episode", label) as bar:
        metrics = run_batch(
            specs, settings, on_episode=lambda e: bar.update(len(specs)), workers=args.workers
        )
    elapsed = time.monotonic() - started

    grid = ResultGrid(specs, metrics)
    rows = table1_rows(grid)
    summary = summarize(grid, args.figure_k)
    write_table1_csv(args.out / "table1.csv", rows)
    markdown = table1_markdown(rows, summary)
    (args.out / "table1.md").write_text(markdown)
    write_episodes_csv(args.out / "episodes.csv", specs, metrics)
    config = {
        "settings": asdict(settings),
        "algos": args.algos,
        "random_steps": args.ks,
        "seeds": seeds,
        "figure_k": args.figure_k,
        "workers": args.workers,
        "elapsed_seconds": round(elapsed, 3),
        "command": [Path(sys.argv[0]).name, *sys.argv[1:]],
    }
    (args.out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    if not args.no_plots:
        from nnql_swarm.experiment.figures import write_figures

        write_figures(args.out, grid, args.figure_k)
    print(markdown)
    report_written(args.out, elapsed)
    return args.out


def build_swarm_parser() -> OneLineParser:
    d = SwarmExperiment()
    parser = OneLineParser(
        prog=f"{program_name()} swarm",
        description="The swarm experiment: every learning preset (the paper's QL and nnQL, the "
        "best options, the shield, n = 2, DAQL, the oracle) over seeds, on the swarm simulator.",
        formatter_class=DefaultsHelpFormatter,
    )
    add = parser.add_argument
    add("--agents", type=bounded(int, 1), default=d.agents, metavar="N", help="agents per swarm")
    add("--seeds", type=bounded(int, 1), default=d.seeds, metavar="N", help="runs per variant")
    add("--seed-base", type=bounded(int, 0), default=d.seed_base, metavar="S",
        help="first seed; seeds are S, S+1, ...")
    add("--episodes", type=bounded(int, 5), default=d.episodes, metavar="N",
        help="episodes of each run (at least 5)")
    add("--max-steps", type=bounded(int, 1), default=d.max_steps, metavar="N",
        help="steps per episode at most")
    add("--grid", type=parse_grid, default=(d.width, d.height), metavar="WxH",
        help=f"grid size, width x height (default: {d.width}x{d.height})")
    add("--obstacle-density", type=float, default=d.obstacle_density, metavar="P",
        help="fraction of the grid's cells that are walls (each seed its own map)")
    add("--on-target", choices=ON_TARGET, default=d.on_target,
        help="what an agent that reached its goal does: park there for good (the paper's "
             "reading) or step aside to make way and come back (the field's)")
    add("--map", default=None, metavar="FILE|SPEC",
        help="every seed on this map: a MovingAI .map file, or random:WxH:P[:SEED], "
             "maze:WxH[:SEED], warehouse[:WxH] (SEED defaults to --seed-base); instead of --grid")
    add("--scen", default=None, metavar="FILE",
        help="with --map: a MovingAI .scen file whose first N lines (N = --agents) are every "
             "episode's starts and goals")
    add("--variants", type=comma_choices(VARIANTS, "variants"), default=d.variants, metavar="LIST",
        help=f"comma-separated, from {', '.join(VARIANTS)} (default: all of them)")
    add("--ablation", action="store_true",
        help="instead of the variants: best-nnql with each of its options beyond the paper "
             "taken back in turn, beside ql, nnql and best-ql")
    add("--walls-ablation", action="store_true",
        help="instead of the variants: the default (path-nnql) with each of its options beyond "
             "shield-nnql taken back in turn, beside shield-ql and shield-nnql")
    add("--out", type=Path, default=None, metavar="DIR",
        help="output directory (default runs/swarm-<time>)")
    add("--force", action="store_true", help="overwrite results already in --out")
    add("--no-plots", action="store_true", help="skip the PNG figures (no matplotlib needed)")
    add("--workers", type=parse_workers, default=None, metavar="N|auto",
        help="threads the runs are spread over (auto: one per core)")
    return parser


def run_swarm(argv: list[str]) -> Path:
    """The swarm experiment's command line: run, then write every result file."""
    parser = build_swarm_parser()
    args = parser.parse_args(argv)
    if args.ablation and args.walls_ablation:
        parser.error("--ablation and --walls-ablation are two tables: choose one")
    presets = ablation_presets() if args.ablation else \
        walls_presets() if args.walls_ablation else dict(PRESETS)
    variants = tuple(presets) if args.ablation or args.walls_ablation else args.variants
    grid = {"width": args.grid[0], "height": args.grid[1]}
    if args.map is not None:
        if args.obstacle_density or args.grid != (SwarmExperiment.width, SwarmExperiment.height):
            parser.error("--map brings its own grid and walls: give no --grid or "
                         "--obstacle-density with it")
        try:
            grid = run_map(args.map, args.scen, args.seed_base, args.agents)
        except ValueError as error:
            parser.error(str(error))
    elif args.scen is not None:
        parser.error("--scen needs --map, the map its scenarios are for")
    experiment = SwarmExperiment(agents=args.agents, seeds=args.seeds, seed_base=args.seed_base,
                                 episodes=args.episodes, max_steps=args.max_steps,
                                 obstacle_density=args.obstacle_density,
                                 on_target=args.on_target, variants=variants, presets=presets,
                                 **grid)
    try:
        experiment.config(experiment.variants[0], experiment.seed_base)
    except ValueError as error:
        parser.error(str(error))
    out = results_folder(parser, args.out, "swarm", (*TABLE_FILES, "config.json"), args.force,
                         plots=not args.no_plots)
    runs = len(experiment.variants) * experiment.seeds
    first = experiment.config(experiment.variants[0], experiment.seed_base)
    prepare_simulator(swarm_world(first), first)
    started = time.monotonic()
    with progress(experiment.episodes, "episode", f"{runs} runs") as bar:
        results = run_experiment(experiment, args.workers, on_episode=lambda _e: bar.update())
    elapsed = time.monotonic() - started
    out.mkdir(parents=True, exist_ok=True)
    write_runs(out, results)
    rows = table_rows(results)
    write_tables(out, results, rows)
    smoothing = max(1, experiment.episodes // 50)
    learning = curves(results, smoothing)
    log_swarm_curves(learning, out / "swarm_curves.rrd")
    if not args.no_plots:
        from nnql_swarm.experiment.figures import write_swarm_figures

        write_swarm_figures(out, learning, experiment.seeds, smoothing)
    config = {"experiment": asdict(experiment), "workers": args.workers,
              "elapsed_seconds": round(elapsed, 3),
              "command": [Path(sys.argv[0]).name, *sys.argv[1:]]}
    (out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    print((out / "swarm_table.md").read_text())
    report_written(out, elapsed)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    signal.signal(signal.SIGTERM, raise_terminated)
    try:
        if argv[:1] == ["swarm"]:
            run_swarm(argv[1:])
            return 0
        if argv[:1] == ["maps"]:
            try:
                run_maps(argv[1:])
            except KeyboardInterrupt:
                return EXIT_INTERRUPTED
            except Terminated:
                return EXIT_TERMINATED
            return 0
        parser = build_parser()
        args = resolve(parser.parse_args(argv[1:] if argv[:1] == ["paper"] else argv), parser)
        run(args)
    except KeyboardInterrupt:
        print("\ninterrupted: stopped before writing results", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Terminated:
        print("\nterminated: stopped before writing results", file=sys.stderr)
        return EXIT_TERMINATED
    return 0


if __name__ == "__main__":
    sys.exit(main())
