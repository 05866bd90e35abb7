"""A crowded run's episode view: each agent's path alone, in bands faded by age
(``recording.fading``), read back from a real recording of 32 agents."""

import numpy as np
import rerun as rr

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.agent_entities import CROWDED_FROM, ROUTE, owner_index, owners
from nnql_swarm.recording.blueprint import episode_wide
from nnql_swarm.recording.fading import (
    BANDS, FRESH_STEPS, OLDEST_ALPHA, moved_steps, route_bands,
)
from nnql_swarm.recording.palette import agent_colors
from nnql_swarm.recording.world import legend
from nnql_swarm.world.metrics import read_episodes
from tests.swarm_helpers import run_swarm


def test_the_newest_steps_are_one_opaque_band_and_the_older_fade_in_bands():
    bands = route_bands(100)
    assert bands[-1] == (100 - FRESH_STEPS, 100, 255)
    assert len(bands) == BANDS + 1 and bands[0][:1] == (0,) and bands[0][2] == OLDEST_ALPHA
    assert all(a[1] == b[0] for a, b in zip(bands, bands[1:]))  # joined, cell to cell
    assert [alpha for *_, alpha in bands] == sorted({alpha for *_, alpha in bands})


def test_a_short_episode_is_one_opaque_band_and_an_empty_one_none():
    assert route_bands(FRESH_STEPS) == [(0, FRESH_STEPS, 255)]
    assert route_bands(0) == []


def test_an_agent_that_stood_still_has_its_own_newest_steps():
    cells = np.zeros((11, 3, 2))
    cells[1:, 0, 0] = 1  # agent 0 moved in the first step only
    cells[1:, 1, 0] = np.arange(1, 11)  # agent 1 every step; agent 2 never
    assert moved_steps(cells).tolist() == [1, 10, 0]


def test_a_crowded_episode_view_shows_the_routes_and_a_smaller_one_every_move_and_wait():
    crowded = SwarmConfig(n_agents=CROWDED_FROM, width=16, height=16)
    assert not [path for path in episode_wide(crowded) if path.startswith("world/agents/")]
    assert "`tick` timeline only" in legend(crowded)
    fewer = SwarmConfig(n_agents=CROWDED_FROM - 1, width=16, height=16)
    assert {path.rsplit("/", 1)[-1] for path in episode_wide(fewer)
            if path.startswith("world/agents/")} == {"path", "intent", "waits"}
    assert "`tick` timeline only" not in legend(fewer)


def test_a_crowded_runs_routes_are_recorded_at_each_episodes_end_and_cleared_at_its_start(
        tmp_path):
    result = run_swarm(tmp_path / "run", "--agents", str(CROWDED_FROM), "--grid", "16x16",
                       "--episodes", "2", "--max-steps", "60", "--seed", "2", "--in-process")
    assert result.returncode == 0, result.stderr
    rows = {}  # tick: agent 3's route strips and their alphas (its entity's, of its colour)
    entity = f"{owners(CROWDED_FROM)[owner_index(CROWDED_FROM)[3]][0]}/{ROUTE}"
    red, green, blue = (int(v) for v in agent_colors(CROWDED_FROM)[3])
    rgb = red << 16 | green << 8 | blue
    for chunk in rr.chunk.RrdReader(tmp_path / "run" / "run.rrd").stream():
        if chunk.is_static or chunk.entity_path.lstrip("/") != entity:
            continue
        batch = chunk.to_record_batch()
        for tick, strips, colours in zip(batch.column("tick").to_pylist(),
                                         batch.column("LineStrips2D:strips").to_pylist(),
                                         batch.column("LineStrips2D:colors").to_pylist()):
            own = [(s, c) for s, c in zip(strips or [], colours or []) if c >> 8 == rgb]
            rows[tick] = ([s for s, _ in own], [c & 0xFF for _, c in own])
    episodes = read_episodes(tmp_path / "run" / "episodes.csv")
    first = 0
    for row in episodes:
        end = int(row["end_tick"])
        assert rows[first] == ([], [])  # cleared as the episode starts
        strips, alphas = rows[end]
        assert strips and alphas[-1] == 255
        path = np.concatenate([np.array(s) for s in strips])
        assert len(strips) == len(route_bands(len(path) - len(strips)))  # its steps, in bands
        assert len(path) - len(strips) <= int(row["steps"])  # to its last move
        assert (np.abs(np.diff(path, axis=0)).sum(axis=1) <= 1).all()  # a step at a time
        assert np.any(path[-1] != path[-2])  # ending with a move
        first = end + 1
