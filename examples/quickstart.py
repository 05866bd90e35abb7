#!/usr/bin/env python3
"""The Python API in one script: run a swarm in this process, read its episodes and Q-tables,
then run the same swarm as real processes over Zenoh and check that it is the same run.

    .venv/bin/python examples/quickstart.py                  # 8 agents, 100 episodes
    .venv/bin/python examples/quickstart.py --agents 4 --episodes 20 --distributed

Each run goes to its own directory under ``--out`` (``runs/quickstart-<time>``). The notebook
beside it, ``quickstart.ipynb``, does the same and shows the recording inline. docs/api.md
documents the API.
"""

import argparse
import time
from pathlib import Path

import numpy as np

from nnql_swarm.api import DETERMINISTIC_COLUMNS, Swarm


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=100)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", type=Path, default=Path("runs") / f"quickstart-{time.strftime('%Y%m%d-%H%M%S')}")
    p.add_argument("--distributed", action="store_true",
                   help="also run it as a world and one process per agent, and compare")
    options = p.parse_args()

    # The options are launch/swarm.py's, by name; a bad one raises ValueError with its line.
    swarm = Swarm(agents=options.agents, episodes=options.episodes,
                  max_steps=options.max_steps, seed=options.seed)
    print(f"config: {swarm.config.run_id}: {swarm.config.n_agents} agents, "
          f"{swarm.config.episodes} episodes, algo {swarm.config.algo}")

    def progress(row: dict) -> None:  # called as each episode ends
        if (row["episode"] + 1) % max(1, options.episodes // 5) == 0:
            print(f"  episode {row['episode']}: {row['arrived']}/{options.agents} arrived, "
                  f"{row['collisions']} collisions")

    run = swarm.run(options.out / "in-process", progress=progress)

    episodes = run.episodes  # a numpy structured array: one element per episode
    print(f"episodes: {episodes.shape[0]} rows, columns {', '.join(episodes.dtype.names)}")
    late = episodes[-max(1, len(episodes) // 5):]
    print(f"last {len(late)} episodes: {late['arrived'].mean() / options.agents:.2f} of the "
          f"agents arrived, {late['collisions'].sum()} collisions, steps "
          f"{late['agent_steps'].sum() / max(1, late['shortest_sum'].sum()):.2f} x the shortest")

    q_ds, q_ca = run.q_tables(0)
    print(f"agent 0: Q_DS {q_ds.shape}, Q_CA {q_ca.shape}, all finite: "
          f"{bool(np.isfinite(q_ds).all() and np.isfinite(q_ca).all())}")
    if run.config.shared:
        shared = run.shared_table()
        print(f"shared table: equal to agent 0's: "
              f"{all(np.array_equal(a, b) for a, b in zip(shared, (q_ds, q_ca)))}")
    print(f"recording: {run.recording}")

    if not options.distributed:
        return 0
    distributed = swarm.run(options.out / "distributed", distributed=True)
    columns = list(DETERMINISTIC_COLUMNS)
    same_rows = bool(np.array_equal(distributed.episodes[columns], episodes[columns]))
    same_tables = all(np.array_equal(a, b)
                      for agent in range(options.agents)
                      for a, b in zip(distributed.q_tables(agent), run.q_tables(agent)))
    print(f"distributed: {distributed.path}: same episodes as in-process: {same_rows}, "
          f"same Q-tables: {same_tables}")
    return 0 if same_rows and same_tables else 1


if __name__ == "__main__":  # the distributed run's processes import this file again
    raise SystemExit(main())
