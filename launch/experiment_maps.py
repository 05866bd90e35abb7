"""``launch/experiment.py maps``: the field's benchmark (``experiment.maps_benchmark``, POGEMA's
protocol) from the command line: its options, and a run written to its output directory. With
``--suite pogema`` frozen play is on POGEMA's published instances (``experiment.pogema``; with
``--tasks lifelong`` its lifelong ones, ``experiment.pogema_lifelong``), and the options left unset
take that suite's defaults (``SUITE_DEFAULTS``)."""

import argparse
import functools
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from nnql_swarm.experiment import pogema, pogema_lifelong
from nnql_swarm.experiment.maps_benchmark import (
    FAMILIES, REFERENCE, SUITES, TABLE_FILES, MapsBenchmark, Recorder, episodes_total,
    learning_curves, map_spec, play_held_out, run_benchmark, run_config, scratch, table_rows,
    write_curves, write_tables,
)
from nnql_swarm.protocol.config import (
    DEFAULT_PRESET, LEARNING_FIELDS, ON_TARGET, PRESETS, TASKS,
)
from nnql_swarm.recording.curves import log_swarm_curves
from nnql_swarm.sim.runs import swarm_world, threads
from nnql_swarm.launch.cli import (
    DefaultsHelpFormatter, OneLineParser, Terminated, bounded, comma_choices,
    parse_workers, prepare_simulator, program_name, progress, report_written, results_folder,
)
from nnql_swarm.world.terrain import MapError
from nnql_swarm.world.pogema_instances import FAMILIES as POGEMA_FAMILIES
from nnql_swarm.world.pogema_instances import INSTANCES

ALL_FAMILIES = (*FAMILIES, *(f for f in POGEMA_FAMILIES if f not in FAMILIES))
_D = MapsBenchmark()
SUITE_DEFAULTS: dict[str, dict[str, Any]] = {
    "project": {"families": _D.families, "agents": _D.agents, "instances": _D.instances,
                "max_steps": _D.max_steps, "on_target": _D.on_target,
                "scratch_agents": _D.scratch_agents},
    "pogema": {"families": tuple(POGEMA_FAMILIES), "agents": (), "instances": 128,
               "max_steps": 0, "on_target": "step-aside", "scratch_agents": ()},
}
"""Each suite's value of the options left unset: on POGEMA's instances every family, at its
published agent counts (``agents`` empty) and step limit (``max_steps`` 0), all 128 instances,
the field's on-target rule, no learning from scratch. With ``--tasks lifelong`` the counts and
step limit are the family's lifelong ones."""

def parse_counts(text: str) -> tuple[int, ...]:
    """``"8,32,64"`` -> agent counts, each 1..1024 (``none``: no count)."""
    if text.strip() == "none":
        return ()
    try:
        counts = tuple(sorted({int(v) for v in text.split(",") if v.strip()}))
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a list of whole numbers: {text!r}") from None
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"agent counts must be at least 1: {text!r}")
    return counts


def parse_override(text: str) -> tuple[str, object]:
    """``OPTION=VALUE`` -> a learning option (``LEARNING_FIELDS``) and its value, of the
    option's type."""
    name, _, value = text.partition("=")
    name = name.strip().replace("-", "_")
    if name not in LEARNING_FIELDS or name == "algo" or not value:
        raise argparse.ArgumentTypeError(
            f"expected OPTION=VALUE with OPTION one of "
            f"{', '.join(f for f in LEARNING_FIELDS if f != 'algo')}, got {text!r}")
    kind = type(PRESETS[DEFAULT_PRESET][name])
    try:
        if kind is bool:
            if value.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return name, value.lower() in ("true", "1")
        return name, kind(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{name} takes a {kind.__name__}, got {value!r}") from None


def build_maps_parser() -> OneLineParser:
    d = MapsBenchmark()
    parser = OneLineParser(
        prog=f"{program_name()} maps",
        description="The field's benchmark (POGEMA's protocol): learn on random training maps, "
        "play the learned tables frozen (no learning, no random step) on held-out random maps, "
        "mazes and the warehouse at each agent count, beside the oracle and the paper's QL; and "
        "learn from scratch on an unseen random map.",
        formatter_class=DefaultsHelpFormatter,
    )
    add = parser.add_argument
    add("--suite", choices=SUITES, default="project",
        help="frozen play on held-out maps of our generators (project) or on POGEMA's published "
             "instances, maps/pogema (pogema: its families random,mazes,warehouse,movingai, the "
             "published agent counts and steps, step-aside, the table beside the published "
             "figures)")
    add("--tasks", choices=TASKS, default=d.tasks,
        help="frozen play on one-shot instances or, with --suite pogema, on POGEMA's lifelong "
             "instances (maps/pogema/*/lifelong: a new goal on every arrival, scored by "
             "throughput; training stays one-shot on our maps)")
    add("--preset", default=DEFAULT_PRESET, choices=list(PRESETS),
        help="the learner benchmarked (beside ql and the oracle); oracle: the oracle alone, "
             "nothing trained")
    add("--seeds", type=bounded(int, 1), default=d.seeds, metavar="N",
        help="policies, each trained and tested on maps of its own")
    add("--seed-base", type=bounded(int, 0), default=d.seed_base, metavar="S",
        help="first seed; seeds are S, S+1, ...")
    add("--train-maps", type=bounded(int, 1), default=d.train_maps, metavar="N",
        help="random training maps per seed")
    add("--train-episodes", type=bounded(int, 1), default=d.train_episodes, metavar="N",
        help="episodes on each training map")
    add("--train-agents", type=bounded(int, 1, 1024), default=d.train_agents, metavar="N",
        help="agents on each training map")
    add("--test-maps", type=bounded(int, 1), default=d.test_maps, metavar="N",
        help="held-out maps per family and seed")
    add("--instances", type=bounded(int, 1), default=argparse.SUPPRESS, metavar="N",
        help=f"episodes on each held-out map (new starts and goals; the map forgotten before "
             f"each; default {d.instances}); --suite pogema: the first N instances of each "
             f"family (default 128)")
    add("--agents", type=parse_counts, default=argparse.SUPPRESS, metavar="LIST",
        help=f"agent counts of frozen play, e.g. 8,32,64 (default {','.join(map(str, d.agents))}; "
             f"--suite pogema: each family's published counts)")
    add("--families", type=comma_choices(ALL_FAMILIES, "families"), default=argparse.SUPPRESS, metavar="LIST",
        help=f"held-out map families, from {','.join(FAMILIES)} (default all); --suite pogema: "
             f"from {','.join(POGEMA_FAMILIES)} (default all)")
    add("--scratch-episodes", type=bounded(int, 5), default=d.scratch_episodes, metavar="N",
        help="episodes of learning from scratch on an unseen random map (--tasks lifelong: on "
             "POGEMA's first random lifelong instance)")
    add("--scratch-agents", type=parse_counts, default=argparse.SUPPRESS, metavar="LIST|none",
        help=f"agent counts of learning from scratch (default "
             f"{','.join(map(str, d.scratch_agents))}; --suite pogema: none)")
    add("--max-steps", type=bounded(int, 1), default=argparse.SUPPRESS, metavar="N",
        help=f"an episode's steps at most (default {d.max_steps}; --suite pogema: the family's, "
             f"128, 256 on MovingAI; lifelong: 256, 128 on the mazes)")
    add("--on-target", choices=ON_TARGET, default=argparse.SUPPRESS,
        help=f"what an arrived agent does, for every variant: stays for good (park) or may make "
             f"way and come back (step-aside, the field's rule; default {d.on_target}, "
             f"--suite pogema: step-aside)")
    add("--pogema-dir", type=Path, default=INSTANCES, metavar="DIR",
        help="--suite pogema: the converted instances (default: the repository's "
             "maps/pogema; maps/pogema/README.md)")
    add("--set", dest="overrides", action="append", type=parse_override, default=[],
        metavar="OPTION=VALUE",
        help="a learning option of the preset changed (repeatable; e.g. beta=0.7, "
             "wait_rule=reach, interaction_radius=3)")
    add("--out", type=Path, default=None, metavar="DIR",
        help="output directory (default runs/maps-<time>)")
    add("--force", action="store_true", help="overwrite results already in --out")
    add("--workers", type=parse_workers, default=None, metavar="N|auto",
        help="threads the runs are spread over (auto: one per core)")
    return parser


def run_maps(argv: list[str]) -> Path:
    """The maps benchmark's command line: every episode written as it is played, then the table
    and the learning curves."""
    parser = build_maps_parser()
    args = parser.parse_args(argv)
    presets = dict(PRESETS)
    learner = args.preset
    if args.overrides:
        learner = args.preset + "[" + ",".join(f"{k}={v}" for k, v in args.overrides) + "]"
        presets[learner] = {**PRESETS[args.preset], **dict(args.overrides)}
    if args.preset == REFERENCE:
        if args.overrides:
            parser.error("--set changes a learner's options; --preset oracle has none")
        learners: tuple[str, ...] = ()
    else:
        learners = (learner,) if learner == "ql" else (learner, "ql")
    chosen = {k: getattr(args, k, default) for k, default in SUITE_DEFAULTS[args.suite].items()}
    bench = MapsBenchmark(presets=presets, seeds=args.seeds, seed_base=args.seed_base, learners=learners,
                          train_maps=args.train_maps, train_episodes=args.train_episodes,
                          train_agents=args.train_agents, test_maps=args.test_maps,
                          scratch_episodes=args.scratch_episodes, suite=args.suite,
                          tasks=args.tasks, **chosen)
    suite = pogema_lifelong if bench.lifelong else pogema
    play = pogema_lifelong.play_lifelong if bench.lifelong else pogema.play_pogema
    frozen_play = (functools.partial(play, directory=args.pogema_dir)
                   if bench.suite == "pogema" else play_held_out)
    from_scratch = (functools.partial(pogema_lifelong.scratch_lifelong, directory=args.pogema_dir)
                    if bench.lifelong else scratch)
    try:
        bench.check()
        first = bench.test_map_seeds(bench.seed_base)[0]
        if bench.suite == "pogema":
            suite.check(bench, args.pogema_dir)
        for family in bench.families if bench.suite == "project" else ("random",):
            for agents in (*bench.agents, *bench.scratch_agents):
                run_config(bench, bench.variants[0], map_spec(family, first), first, agents, 1,
                           True)
        train_seed = bench.train_map_seeds(bench.seed_base)[0]
        run_config(bench, bench.variants[0], map_spec("random", train_seed), train_seed,
                   bench.train_agents, 1, False)
    except (ValueError, MapError) as error:
        parser.error(str(error))
    out = results_folder(parser, args.out, "maps",
                         (*TABLE_FILES, "maps_episodes.csv", "config.json"), args.force)
    config = {"benchmark": {k: v for k, v in asdict(bench).items() if k != "presets"},
              "presets": {v: presets[v] for v in bench.variants}, "workers": args.workers,
              **({"pogema_dir": str(args.pogema_dir)} if bench.suite == "pogema" else {}),
              "command": [Path(sys.argv[0]).name, *sys.argv[1:]]}
    (out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    for name in TABLE_FILES:
        (out / name).unlink(missing_ok=True)
    train_seed = bench.train_map_seeds(bench.seed_base)[0]
    warm = run_config(bench, bench.variants[0], map_spec("random", train_seed), train_seed,
                      bench.train_agents, 1, False)
    prepare_simulator(swarm_world(warm), warm)
    started = time.monotonic()
    recorder = Recorder(out / "maps_episodes.csv")
    try:
        with threads(args.workers), progress(episodes_total(bench), "run-episode",
                                              f"{bench.seeds} seeds") as bar:
            run_benchmark(bench, recorder, on_episode=bar.update, policies=out / "policies",
                          frozen_play=frozen_play, from_scratch=from_scratch)
    except (KeyboardInterrupt, Terminated):
        recorder.close()
        print(f"\ninterrupted: the episodes played so far are in {out}/maps_episodes.csv",
              file=sys.stderr)
        raise
    recorder.close()
    elapsed = time.monotonic() - started
    rows = table_rows(bench, recorder.rows)
    write_tables(out, bench, rows, elapsed,
                 suite.markdown(bench, rows, elapsed) if bench.suite == "pogema" else None)
    curves = learning_curves(bench, recorder.rows)
    write_curves(out / "maps_curves.csv", curves)
    log_swarm_curves(curves, out / "maps_curves.rrd", recording_id="maps-benchmark")
    config["elapsed_seconds"] = round(elapsed, 3)
    (out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    print((out / "maps_table.md").read_text())
    report_written(out, elapsed)
    return out
