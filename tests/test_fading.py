"""A crowded run's episode view: each agent's path alone, faded by age (``recording.fading``),
read back from a real recording of 32 agents."""

import numpy as np
import rerun as rr

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.agent_entities import CROWDED_FROM, PATH, agents_of
from nnql_swarm.recording.blueprint import episode_wide
from nnql_swarm.recording.fading import FRESH_STEPS, OLDEST_ALPHA, path_alpha
from nnql_swarm.recording.world import legend
from tests.swarm_helpers import run_swarm


def test_the_newest_steps_are_opaque_and_the_first_the_faintest():
    steps = np.arange(101)
    alpha = path_alpha(steps, np.zeros_like(steps))
    assert alpha[0] == OLDEST_ALPHA and (alpha[-FRESH_STEPS:] == 255).all()
    assert alpha[-FRESH_STEPS - 1] < 255 and (np.diff(alpha.astype(int)) >= 0).all()


def test_each_episode_fades_from_its_own_newest_step():
    alpha = path_alpha([0, 1, 40, 0, 1, 2], [3, 3, 3, 4, 4, 4])
    assert alpha.tolist() == [OLDEST_ALPHA, path_alpha([1, 40], [0, 0])[0], 255, 255, 255, 255]


def test_a_crowded_episode_view_shows_the_paths_alone_and_a_smaller_one_every_move_and_wait():
    crowded = SwarmConfig(n_agents=CROWDED_FROM, width=16, height=16)
    parts = {path.rsplit("/", 1)[-1] for path in episode_wide(crowded)
             if path.startswith("world/agents/")}
    assert parts == {PATH}
    assert "tick` timeline only" in legend(crowded)
    fewer = SwarmConfig(n_agents=CROWDED_FROM - 1, width=16, height=16)
    assert {path.rsplit("/", 1)[-1] for path in episode_wide(fewer)
            if path.startswith("world/agents/")} == {"path", "intent", "waits"}


def test_a_crowded_runs_paths_are_recorded_faded_by_age(tmp_path):
    result = run_swarm(tmp_path / "run", "--agents", str(CROWDED_FROM), "--grid", "16x16",
                       "--episodes", "2", "--max-steps", "60", "--seed", "2", "--in-process")
    assert result.returncode == 0, result.stderr
    rows = []  # (tick, episode, alpha) of agent 0's path
    for chunk in rr.chunk.RrdReader(tmp_path / "run" / "run.rrd").stream():
        agents = agents_of(chunk.entity_path, CROWDED_FROM)
        if agents is None or chunk.is_static or not chunk.entity_path.endswith(f"0/{PATH}"):
            continue
        batch = chunk.to_record_batch()
        colours = batch.column("LineStrips2D:colors").to_pylist()
        rows += [(tick, episode, colour[0] & 0xFF) for tick, episode, colour in zip(
            batch.column("tick").to_pylist(), batch.column("episode").to_pylist(), colours)]
    assert rows
    for episode in (0, 1):
        alphas = [alpha for _, e, alpha in sorted(rows) if e == episode]
        assert alphas[-1] == 255 and alphas[0] < 255 and alphas == sorted(alphas)
