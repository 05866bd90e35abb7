#!/usr/bin/env python3
"""Where frozen play's collisions come from: the maps benchmark's frozen phase, each collision
classified from the simulator's trace.

For each seed the learner (``--preset``, with ``--set`` options) is trained as the maps benchmark
trains it (``experiment.maps_benchmark.train``), then played frozen on the seed's held-out random maps at
``--agents``, every tick recorded. Each learner that collided in a step is classified by what it
did and what stood where it went:

- ``stayed, hit``: it stayed and another moved into it;
- ``into a wall`` / ``into a parked agent``;
- ``swap``: it and the occupant of its target aimed at each other's cells;
- ``into one that stayed, intent known`` / ``... unknown, seen still`` / ``... unknown, seen
  moving`` / ``... unknown, unseen last step``: the occupant chose to stay;
- ``into one that was blocked``: the occupant tried to move and could not (a chain pushed);
- ``two into one free cell`` (``, other's intent known`` when this agent knew the other was
  heading there), ``two into a cell being left``: someone else moved into the same cell.

Each moving collider is also marked ``shield gave up`` when its move was one the shield's rules
forbid (``learning.readings.forbids``): frozen play takes no random step, so the shield forbade
every action and gave up.

    python -m bench.collisions --agents 32 --seeds 1 --set still_shield=true
"""

import argparse
from collections import Counter

import numpy as np

from nnql_swarm.experiment.maps_benchmark import MapsBenchmark, Recorder, map_spec, run_config, train
from nnql_swarm.learning.fields import (
    LP_ESCAPE_SHIELD, LP_READING, LP_STILL_SHIELD, NB_FIELDS, NB_KNOWN, NB_PREV_X, NB_PREV_Y,
    learner_params,
)
from nnql_swarm.learning.readings import forbids
from nnql_swarm.protocol.actions import STAY, target_x, target_y
from nnql_swarm.protocol.config import PRESETS
from nnql_swarm.sim.runs import Batch, swarm_world
from nnql_swarm.sim.episode import (
    TR_ACTION, TR_ARRIVED, TR_COLLIDED, TR_GOAL_X, TR_GOAL_Y, TR_X, TR_Y, EpisodeRules, Moves,
    neighbour_rows,
)
from nnql_swarm.world.rules import Bodies

rows_of = getattr(neighbour_rows, "py_func", neighbour_rows)
"""The simulator's neighbour rows as plain Python (the calls it makes stay compiled)."""


def classify(batch: Batch, run: int, first_tick: int, steps: int, tally: Counter) -> None:
    """Add the collisions of the episode just played (``batch.trace``) to ``tally``."""
    w, config = batch.world, batch.runs[run]
    n, learners = w.bodies, w.learners
    params = np.array(learner_params(config)[0], dtype=np.int64)
    trace = batch.trace[run]
    learns = np.arange(n) < learners
    rules = EpisodeRules(n, learners, w.width, w.height, w.max_steps, w.count_swaps,
                         w.goal_reward, w.stay_reward, True, w.lifelong, w.max_steps)
    options = batch.options[run]
    nb = np.zeros((n, NB_FIELDS), dtype=np.int64)
    for s in range(steps):
        x, y = trace[s, :, TR_X].copy(), trace[s, :, TR_Y].copy()
        actions = trace[s, :, TR_ACTION].copy()
        arrived = trace[s, :, TR_ARRIVED].astype(bool)
        goal_x, goal_y = trace[s, :, TR_GOAL_X].copy(), trace[s, :, TR_GOAL_Y].copy()
        collided = trace[s, :, TR_COLLIDED].astype(bool)
        if s:
            prev_x, prev_y = trace[s - 1, :, TR_X].copy(), trace[s - 1, :, TR_Y].copy()
        else:
            prev_x, prev_y = np.full(n, -1, dtype=np.int64), np.full(n, -1, dtype=np.int64)
        tx = np.array([target_x(x[i], actions[i], w.width) for i in range(n)])
        ty = np.array([target_y(y[i], actions[i], w.height) for i in range(n)])
        occupant = {(x[i], y[i]): i for i in range(n)}
        tick = first_tick + s
        for i in range(learners):
            if not collided[i]:
                continue
            if (tx[i], ty[i]) == (x[i], y[i]):
                tally["stayed, hit"] += 1
                continue
            rank = (i - tick) % learners
            decided = np.array([j >= learners or (j - tick) % learners < rank for j in range(n)])
            bodies = Bodies(x, y, goal_x, goal_y, learns, arrived, np.zeros(n, dtype=np.int64))
            moves = Moves(actions, decided, prev_x, prev_y, np.zeros(n, dtype=np.int64),
                          np.zeros(n, dtype=bool))
            m = rows_of(i, tick, rules, bodies, moves, batch.q_ds[run], nb, params, options,
                        True)
            rows = {int(nb[k][0]): nb[k] for k in range(m)}
            gave_up = forbids(params[LP_READING], params[LP_STILL_SHIELD],
                              params[LP_ESCAPE_SHIELD], x[i], y[i], actions[i], nb, m, w.width,
                              w.height)
            j = occupant.get((tx[i], ty[i]))
            if j is not None and j >= learners:
                kind = "into a wall"
            elif j is not None and arrived[j]:
                kind = "into a parked agent"
            elif j is not None and (tx[j], ty[j]) == (x[i], y[i]):
                kind = "swap"
            elif j is not None and actions[j] == STAY:
                row = rows.get(j)
                if row is not None and row[NB_KNOWN]:
                    kind = "into one that stayed, intent known"
                elif row is None or row[NB_PREV_X] < 0:
                    kind = "into one that stayed, unknown, unseen last step"
                elif (row[NB_PREV_X], row[NB_PREV_Y]) == (x[j], y[j]):
                    kind = "into one that stayed, unknown, seen still"
                else:
                    kind = "into one that stayed, unknown, seen moving"
            elif j is not None and collided[j] and (tx[j], ty[j]) != (x[j], y[j]):
                kind = "into one that was blocked"
            else:
                others = [k for k in range(n) if k != i and (tx[k], ty[k]) == (tx[i], ty[i])
                          and (tx[k], ty[k]) != (x[k], y[k])]
                known = any(k in rows and rows[k][NB_KNOWN] for k in others)
                kind = ("two into a cell being left" if j is not None
                        else "two into one free cell" + (", other's intent known" if known else ""))
            tally[kind + (" (shield gave up)" if gave_up else "")] += 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="path-nnql")
    parser.add_argument("--agents", type=int, default=32)
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--seed-base", type=int, default=0)
    parser.add_argument("--set", action="append", default=[], metavar="OPTION=VALUE",
                        help="a learning option changed (bool as true/false)")
    args = parser.parse_args()
    preset = dict(PRESETS[args.preset])
    for item in args.set:
        name, _, value = item.partition("=")
        kind = type(preset[name])
        preset[name] = value.lower() in ("true", "1") if kind is bool else kind(value)
    presets = {**PRESETS, args.preset: preset}
    tally: Counter = Counter()
    total = 0
    for seed in range(args.seed_base, args.seed_base + args.seeds):
        bench = MapsBenchmark(seeds=1, seed_base=seed, learners=(args.preset,), presets=presets)
        tables = train(bench, seed, Recorder(None))
        for map_seed in bench.test_map_seeds(seed):
            spec = map_spec("random", map_seed)
            config = run_config(bench, args.preset, spec, map_seed, args.agents,
                                bench.instances, frozen=True)
            batch = Batch(swarm_world(config), [config], record=True)
            batch.load_tables(0, *tables[args.preset])
            for _ in range(bench.instances):
                batch.forget_maps()
                first_tick = int(batch.tick[0])
                episodes = batch.play(1)
                total += int(episodes.collisions[0, -1])
                classify(batch, 0, first_tick, int(episodes.steps[0, -1]), tally)
    print(f"{args.preset} {' '.join(args.set)}, {args.agents} agents, seeds {args.seed_base}-"
          f"{args.seed_base + args.seeds - 1}: {total} collisions")
    for kind, count in tally.most_common():
        print(f"  {count:6d}  {kind}")


if __name__ == "__main__":
    main()
