"""What an agent knows of the walls and the way to its goal (``learning.known_map``), by hand on
small maps; destination seeking that reads it (``learning.learner``: the waypoint and progress
states, the path and flat rewards, the detour around parked agents, the push); and the runs it
plays, the same each time and checkpointed."""

import numpy as np
import pytest

from nnql_swarm.agent.brain import AgentBrain
from nnql_swarm.learning.known_map import (
    MAP_CUT, MAP_KNOWN, WHOLE_MAP, check_cell_order, fresh_map, known_cells, map_size, path_length,
    progress_moves, restore_known, see_walls, track, waypoint_move,
)
from nnql_swarm.learning.fields import (
    LP_WALL_SIGHT, learner_params,
    DS_PROGRESS, DS_WAYPOINT, LP_DS_REWARD, LP_DS_STATE, LP_STILL_TERMINAL, NB_FIELDS, REC_GOAL,
    REC_NEXT_GOAL, REC_TERMINAL, REWARD_FLAT, REWARD_PATH, RF_R_DS,
)
from nnql_swarm.learning.readings import ds_state
from nnql_swarm.protocol.actions import DOWN, RIGHT, STAY, UP, VIEW_RADIUS, offset_state
from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.sim.runs import Batch, swarm_world

from tests.test_learner import NEVER, Agent, neighbour

W = H = 7
NONE = np.zeros((0, NB_FIELDS), np.int64)


def fresh(width=W, height=H):
    wmap = np.zeros(map_size(width, height), np.int64)
    fresh_map(wmap)
    return wmap


def walls_of(*cells):
    return np.array([c[0] for c in cells], np.int64), np.array([c[1] for c in cells], np.int64)


def parked(j, x, y):
    return neighbour(j, x, y, parked=True)


def test_a_wall_is_known_once_it_was_in_view_and_stays_known():
    wmap = np.zeros(map_size(30, 3), np.int64)
    fresh_map(wmap)
    wx, wy = walls_of((12, 1), (25, 1))
    see_walls(wmap, wx, wy, 0, 2, 1, 1, 30, VIEW_RADIUS)
    assert known_cells(wmap, 30, 3) == [], "11 columns away: out of view"
    see_walls(wmap, wx, wy, 0, 2, 2, 1, 30, VIEW_RADIUS)
    assert known_cells(wmap, 30, 3) == [42]
    see_walls(wmap, wx, wy, 0, 2, 15, 1, 30, VIEW_RADIUS)
    assert known_cells(wmap, 30, 3) == [42, 55] and wmap[MAP_KNOWN] == 2
    see_walls(wmap, wx, wy, 0, 2, 0, 0, 30, VIEW_RADIUS)
    assert known_cells(wmap, 30, 3) == [42, 55], "what was seen is kept"
    again = np.zeros_like(wmap)
    restore_known(again, known_cells(wmap, 30, 3), 30, 3)
    assert known_cells(again, 30, 3) == [42, 55] and again[MAP_KNOWN] == 2


def test_an_agent_that_knows_the_map_knows_every_wall_at_its_first_look():
    """``--map-known``: the sight is the whole map, however far a wall is."""
    wmap = np.zeros(map_size(30, 3), np.int64)
    fresh_map(wmap)
    wx, wy = walls_of((12, 1), (25, 1))
    see_walls(wmap, wx, wy, 0, 2, 0, 0, 30, WHOLE_MAP)
    assert known_cells(wmap, 30, 3) == [42, 55]
    config = SwarmConfig(**{**PRESETS["pibt-nnql"], "map_known": True})
    assert learner_params(config)[0][LP_WALL_SIGHT] == WHOLE_MAP
    assert learner_params(SwarmConfig())[0][LP_WALL_SIGHT] == VIEW_RADIUS


def test_walls_out_of_cell_order_are_refused():
    check_cell_order([(3, 0), (0, 1), (5, 1)])
    with pytest.raises(ValueError, match="cell order"):
        check_cell_order([(0, 1), (3, 0)])


def test_the_path_goes_around_the_known_walls_and_through_the_unknown():
    # a wall from (3, 0) to (3, 5): the way from (1, 1) to (5, 1) goes down to row 6
    wall = [(3, y) for y in range(6)]
    wx, wy = walls_of(*wall)
    wmap = fresh()
    track(wmap, wx, wy, 0, len(wall), 1, 1, 5, 1, W, H, NONE, 0, -1, False, VIEW_RADIUS)
    assert path_length(wmap, 1, 1, W, H) == 14  # down 5, across 4, up 5
    assert progress_moves(wmap, 1, 1, W, H) == (1 << DOWN) | (1 << RIGHT)
    assert waypoint_move(wmap, 1, 1, 5, 1, W, H) == RIGHT, "the goal is farther across"
    assert waypoint_move(wmap, 2, 1, 5, 1, W, H) == DOWN and path_length(wmap, 2, 1, W, H) == 13
    assert waypoint_move(wmap, 5, 1, 5, 1, W, H) == STAY and progress_moves(wmap, 5, 1, W, H) == 0
    # the same wall unseen (none passed): straight across
    blind = fresh()
    track(blind, wx, wy, 0, 0, 1, 1, 5, 1, W, H, NONE, 0, -1, False, VIEW_RADIUS)
    assert path_length(blind, 1, 1, W, H) == 4 and waypoint_move(blind, 1, 1, 5, 1, W, H) == RIGHT


def test_the_waypoint_breaks_ties_along_the_axis_where_the_goal_is_farther():
    wmap = fresh()
    track(wmap, *walls_of(), 0, 0, 1, 1, 5, 3, W, H, NONE, 0, -1, False, VIEW_RADIUS)
    assert progress_moves(wmap, 1, 1, W, H) == (1 << DOWN) | (1 << RIGHT)
    assert waypoint_move(wmap, 1, 1, 5, 3, W, H) == RIGHT
    assert waypoint_move(wmap, 1, 1, 3, 3, W, H) == DOWN, "a diagonal: the vertical move"
    track(wmap, *walls_of(), 0, 0, 1, 1, 1, 5, W, H, NONE, 0, -1, False, VIEW_RADIUS)  # a new goal, a new field
    assert waypoint_move(wmap, 1, 1, 1, 5, W, H) == DOWN and path_length(wmap, 1, 1, W, H) == 4


def test_the_detour_goes_around_parked_agents_within_reach_unless_they_close_the_way():
    wmap = fresh()
    rows = np.array([parked(1, 2, 1)], np.int64)
    track(wmap, *walls_of(), 0, 0, 1, 1, 4, 1, W, H, rows, 1, 4, False, VIEW_RADIUS)
    assert path_length(wmap, 1, 1, W, H) == 5 and waypoint_move(wmap, 1, 1, 4, 1, W, H) == UP
    for rows_again, starts in ((NONE, False), (NONE, True)):
        track(wmap, *walls_of(), 0, 0, 1, 1, 4, 1, W, H, rows_again, 0, 4, starts, VIEW_RADIUS)
        assert path_length(wmap, 1, 1, W, H) == (5 if not starts else 3), \
            "an arrived agent is planned around until the episode ends"
    far = fresh()
    track(far, *walls_of(), 0, 0, 1, 1, 4, 1, W, H, rows, 1, -1, False, VIEW_RADIUS)
    assert path_length(far, 1, 1, W, H) == 3, "no detour asked: straight through"
    # a corridor one cell wide, closed by the arrived agent: the way through it is the only one
    corridor = [(x, y) for y in (0, 2) for x in range(W)]  # walls in cell order
    closed = fresh()
    track(closed, *walls_of(*corridor), 0, len(corridor), 1, 1, 4, 1, W, H, rows, 1, 4, False, VIEW_RADIUS)
    assert path_length(closed, 1, 1, W, H) == 3 and waypoint_move(closed, 1, 1, 4, 1, W, H) == RIGHT


def whole_field(blocked, goal, width, height):
    """The distances to ``goal`` of every cell around the ``blocked`` ones, by a plain search."""
    dist = {goal: 0}
    frontier = [goal]
    while frontier:
        reached = []
        for x, y in frontier:
            for cell in ((x - 1, y), (x + 1, y), (x, y - 1), (x, y + 1)):
                if (0 <= cell[0] < width and 0 <= cell[1] < height and cell not in dist
                        and cell not in blocked):
                    dist[cell] = dist[(x, y)] + 1
                    reached.append(cell)
        frontier = reached
    return dist


@pytest.mark.parametrize("seed", range(12))
def test_the_lazy_field_reads_as_the_whole_field_would(seed):
    """An agent walks about a map of walls while arrived agents are taken as it goes: every
    distance it reads (its cell, the cells next to it, the one it came from) is that cell's in
    the whole field of the map it plans on, although the search stops once those are known."""
    rng = np.random.default_rng(seed)
    width, height = int(rng.integers(6, 16)), int(rng.integers(6, 16))
    walls = [(x, y) for y in range(height) for x in range(width) if rng.random() < 0.2]
    free = [(x, y) for y in range(height) for x in range(width) if (x, y) not in walls]
    wx, wy = walls_of(*walls)
    wmap = fresh(width, height)
    goal = free[rng.integers(len(free))]
    here = free[rng.integers(len(free))]
    came_from = here
    parked_cells: list[tuple[int, int]] = []
    rows = NONE
    for step in range(80):
        if rng.random() < 0.15:
            cell = free[rng.integers(len(free))]
            if cell != here and cell not in parked_cells:
                parked_cells.append(cell)
                rows = np.array([parked(j + 1, *c) for j, c in enumerate(parked_cells)], np.int64)
        if rng.random() < 0.05:  # a new goal
            goal = free[rng.integers(len(free))]
        track(wmap, wx, wy, 0, len(walls), *here, *goal, width, height, rows, len(rows),
              width + height, step == 0, VIEW_RADIUS)
        blocked = set(known_cells_of(wmap, width, height))
        planned = whole_field(blocked | set(parked_cells) if not wmap[MAP_CUT] else blocked,
                              goal, width, height)
        reads = [here, came_from] + [(here[0] + dx, here[1] + dy) for dx, dy in
                                     ((-1, 0), (1, 0), (0, -1), (0, 1))]
        for x, y in reads:
            if 0 <= x < width and 0 <= y < height:
                assert path_length(wmap, x, y, width, height) == planned.get((x, y), -1), \
                    f"step {step}: cell {(x, y)}, the agent at {here}, its goal {goal}"
        moves = [(here[0] + dx, here[1] + dy) for dx, dy in ((-1, 0), (1, 0), (0, -1), (0, 1))]
        moves = [c for c in moves if c in free and c not in parked_cells]
        came_from = here
        if moves:
            here = moves[rng.integers(len(moves))]


def test_an_arrived_agent_the_search_has_not_reached_yet_is_gone_around_when_it_does():
    """A field started with no arrived agent in view, grown only as far as the agent read it;
    an agent arrives beyond, where the search has not been: as the agent walks out towards it,
    the search goes around it, as a whole field would."""
    width, height = 10, 2
    wmap = fresh(width, height)
    track(wmap, *walls_of(), 0, 0, 3, 0, 0, 0, width, height, NONE, 0, width, True, VIEW_RADIUS)
    assert path_length(wmap, 3, 0, width, height) == 3
    assert path_length(wmap, 6, 0, width, height) == -1, "not reached yet"
    rows = np.array([parked(1, 6, 0)], np.int64)
    for x in (3, 4, 5):
        track(wmap, *walls_of(), 0, 0, x, 0, 0, 0, width, height, rows, 1, width, False,
              VIEW_RADIUS)
    assert path_length(wmap, 5, 0, width, height) == 5
    assert path_length(wmap, 6, 0, width, height) == -1, "the arrived agent's cell is never entered"
    assert path_length(wmap, 5, 1, width, height) == 6


def known_cells_of(wmap, width, height):
    return [(c % width, c // width) for c in known_cells(wmap, width, height)]


def test_destination_seeking_reads_the_waypoint_or_the_progress_moves():
    agent = Agent()
    agent.wmap = fresh()  # a map of this grid
    agent.params[LP_DS_STATE] = DS_WAYPOINT
    track(agent.wmap, *walls_of(), 0, 0, 1, 1, 5, 3, W, H, NONE, 0, -1, False, VIEW_RADIUS)
    assert ds_state(agent.params, agent.wmap, 1, 1, 5, 3, W, H) == offset_state(1, 0)
    agent.params[LP_DS_STATE] = DS_PROGRESS
    assert ds_state(agent.params, agent.wmap, 1, 1, 5, 3, W, H) == (1 << DOWN) | (1 << RIGHT)


@pytest.mark.parametrize("kind, nearer, same", [(REWARD_FLAT, 1.0, 0.5),
                                                (REWARD_PATH, 1.0 / 3, 0.5 / 3)])
def test_the_map_rewards_read_the_path_length(kind, nearer, same):
    agent = Agent(k=NEVER)
    agent.params[LP_DS_STATE] = DS_WAYPOINT
    agent.params[LP_DS_REWARD] = kind
    agent.params[LP_STILL_TERMINAL] = 1
    agent.q_ds[:] = 1.0
    agent.q_ds[offset_state(1, 0), RIGHT] = 5.0  # the waypoint is right: go right
    assert agent.decide((1, 1), (5, 1)) == RIGHT
    agent.record(0.0, 10.0)  # the world's Euclidean reward is not the one learned
    agent.decide((2, 1), (5, 1))
    assert agent.rec_f[RF_R_DS] == nearer and agent.rec[REC_TERMINAL] == 0
    assert agent.rec[REC_GOAL] == agent.rec[REC_NEXT_GOAL] == offset_state(1, 0), \
        "one state all along a straight path: a move is not taken for a step that went nowhere"
    agent.record(0.0, 0.0)  # blocked: it stayed at (2, 1)
    agent.decide((2, 1), (5, 1))
    assert agent.rec_f[RF_R_DS] == same and agent.rec[REC_TERMINAL] == 1


def known_preset(**extra):
    return {**PRESETS["path-nnql"], **extra}


def test_walls_known_in_a_run_are_the_ones_seen_and_a_run_is_its_seed():
    config = SwarmConfig(n_agents=6, width=26, height=14, seed=4, episodes=3, max_steps=30,
                         obstacle_density=0.2, **known_preset())
    plays = []
    for _ in range(2):
        batch = Batch(swarm_world(config), [config])
        episodes = batch.play(3)
        plays.append((episodes.row.copy(), batch.q_ds.copy(), batch.wmap.copy()))
        walls = {y * 26 + x for x, y in config.walls().tolist()}
        for agent in range(6):
            known = set(batch.known_walls(0, agent))
            assert known and known <= walls
    assert all(np.array_equal(a, b) for a, b in zip(*plays))
    brain = AgentBrain(0, config)
    brain.learner.restore(*batch.tables(0, 0), 0, batch.known_walls(0, 0))
    assert brain.learner.known_walls() == batch.known_walls(0, 0)


def test_a_lookahead_needs_the_goal_offset():
    with pytest.raises(ValueError, match="--ds-state goal"):
        SwarmConfig(lookahead=2, ds_state="waypoint", algo="nnql")
