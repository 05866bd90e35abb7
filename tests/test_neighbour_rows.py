"""The neighbour rows are written by one function (``learning.neighbours.neighbour_row``): the
agent's rows (``neighbour_rows_into``, run by ``learning.rows.NeighbourRows``, which the world
reads too when it checks a learning record) and the simulator's (``sim.episode.neighbour_rows``) alike; no other code writes a row's fields (the
simulator's lookahead overwrites only the cell the state reads). That both give the same runs is
the parity tests' (``tests/test_swarm.py``)."""

import os
import re
from pathlib import Path

import numpy as np

from nnql_swarm.learning import neighbours
from nnql_swarm.learning.rows import NeighbourRows
from nnql_swarm.learning.fields import (
    NB_FIELDS, NB_ID, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_PARKED, NB_PREV_X, NB_PREV_Y, NB_ROW,
    NB_STATE_X, NB_STATE_Y, NB_X, NB_Y,
)
from nnql_swarm.protocol.actions import LEFT, STAY, UP
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.messages import WORLD_SENDER, Observation, pack_ids, pack_neighbours
from tests.swarm_helpers import ROOT

WRITES = re.compile(r"\[(NB_[A-Z_]+)\]\s*=(?!=)")


def test_only_neighbour_row_writes_a_rows_fields():
    written: dict[str, set[str]] = {}
    package = ROOT / "nnql_swarm"
    for folder, _, files in os.walk(package, followlinks=True):  # the rooms are links
        for path in (Path(folder) / name for name in files if name.endswith(".py")):
            for name in WRITES.findall(path.read_text()):
                written.setdefault(name, set()).add(str(path.relative_to(package)))
    rows = "learning/neighbours.py"
    assert all(files == {rows} for name, files in written.items()
               if name not in ("NB_ROW", "NB_STATE_X", "NB_STATE_Y")), written
    assert written["NB_STATE_X"] == written["NB_STATE_Y"] == {rows, "sim/episode.py"}
    assert written["NB_ROW"] == {"learning/readings.py"}  # the Q_CA row, read after
    sources = {path: (ROOT / path).read_text() for path in ("sim/episode.py", rows)}
    assert "neighbour_row(row," in sources["sim/episode.py"]
    assert sources[rows].count("neighbour_row(out[m],") == 2  # the agents', then the walls'


def test_a_row_holds_the_cell_a_known_move_goes_to_and_the_cell_seen_before():
    for row in ([0] * NB_FIELDS, np.zeros(NB_FIELDS, dtype=np.int64)):
        neighbours.write_row(row, 3, 4, 5, True, LEFT, False, 4, 6, 9, 9)
        assert list(row) == [3, 4, 5, 1, 3, 5, 3, 5, 0, 4, 6, 0]
        neighbours.write_row(row, 2, 0, 0, False, LEFT, True, -1, -1, 9, 9)
        assert list(row) == [2, 0, 0, 0, 0, 0, 0, 0, 1, -1, -1, 0]
        neighbours.write_row(row, 2, 0, 0, True, UP, False, -1, -1, 9, 9)  # off the grid: stays
        assert (row[NB_NEXT_X], row[NB_NEXT_Y], row[NB_KNOWN]) == (0, 0, 1)
    assert (NB_ID, NB_X, NB_Y, NB_KNOWN, NB_NEXT_X, NB_NEXT_Y, NB_STATE_X, NB_STATE_Y, NB_PARKED,
            NB_PREV_X, NB_PREV_Y, NB_ROW) == tuple(range(NB_FIELDS))


def test_the_agents_rows_are_its_neighbours_in_reach_then_the_walls_compiled_or_not():
    """An agent's rows of an observation, from one call: the neighbours within reach with their
    answers, parked flags and cells a tick ago, then the walls, each known to stay within the
    negotiation's reach and seen where the agent's cell a tick ago saw it; the same whether the
    kernel is compiled or plain Python."""
    rows_of_map = ["." * 8] * 8
    rows_of_map[1] = "..@....."
    config = SwarmConfig(n_agents=4, width=8, height=8, map_rows=tuple(rows_of_map),
                         interaction_radius=2)
    reader = NeighbourRows(config)
    obs = Observation(run="rows", tick=5, sender=WORLD_SENDER, agent=0, episode=0, step=5,
                      position=(3, 1), goal=(0, 0),
                      neighbours=pack_neighbours([(1, 3, 2), (2, 7, 7), (3, 4, 1)]),
                      rank=2, reward_ds=0.0, reward_ca=10.0, collided=False, arrived=False,
                      episode_end=False, parked=pack_ids([1]))
    expected = [[1, 3, 2, 1, 3, 2, 3, 2, 1, -1, -1, 0],  # known to stay, parked
                [3, 4, 1, 1, 3, 1, 3, 1, 0, 4, 0, 0],  # announced LEFT, seen at (4, 0)
                [4, 2, 1, 1, 2, 1, 2, 1, 0, 2, 1, 0]]  # the wall: known to stay, seen before
    got = reader(obs, {1: STAY, 3: LEFT}, True, {3: (4, 0)}, (3, 0))
    assert [list(map(int, row)) for row in got] == expected  # agent 2 is beyond reach
    plain = np.zeros((reader.size, NB_FIELDS), dtype=np.int64)  # its callees may be compiled
    n = config.n_agents
    m = neighbours.neighbour_rows_into.__dict__.get("py_func", neighbours.neighbour_rows_into)(
        ((1, 3, 2), (2, 7, 7), (3, 4, 1)), 3, reader.reach, reader.reach, [0] * n, (1,), 1, 3, 1,
        reader.reach,
        [-1, STAY, -1, LEFT], [-1, -1, -1, 4], [-1, -1, -1, 0], 3, 0, True,
        reader.wall_ids.tolist(), reader.n_walls, reader.wall_far, 2, config.meet_only, 8, 8,
        plain)
    assert plain[:m].tolist() == expected
    unannounced = reader(obs, {}, False, {}, None)
    assert [int(v) for v in unannounced[-1][:4]] == [4, 2, 1, 0]  # nobody announces: unknown
