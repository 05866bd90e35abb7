"""Rerun recordings of real runs, read back with Rerun's reader: entities, metrics, heat maps."""

import os
import signal
import subprocess
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest
import rerun as rr

from nnql_swarm.agent import agent_checkpoint
from nnql_swarm.recording.agent import (
    OPTIMISTIC, TABLES, UNVISITED, TimedBrain, ds_table, learnable_bound, logs_heat_maps,
    table_picture,
)
from nnql_swarm.learning.saved import read_fields
from nnql_swarm.recording.binary import rerun_binary
from nnql_swarm.recording.curves import log_experiment
from nnql_swarm.transport.runfiles import PARTS_DIR
from nnql_swarm.protocol.actions import RIGHT, STAY, UP, offset_state
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.protocol.messages import WORLD_SENDER, Observation, pack_ids, pack_neighbours
from nnql_swarm.transport.ports import free_port
from tests.swarm_helpers import group_pids, run_swarm, start_swarm
from nnql_swarm.world.metrics import read_episodes
from nnql_swarm.world.scenario import swarm_episode
from nnql_swarm.recording.palette import KEEP_APART, PALETTE, agent_colors
from nnql_swarm.recording.world import METRICS, negotiation_pairs
from nnql_swarm.recording.agent_entities import (
    DISC, GOAL, PER_TICK as PER_TICK_PARTS, START, TRAIL, WAITS,
)

AGENTS, EPISODES = 8, 3
RUN = ("--agents", str(AGENTS), "--episodes", str(EPISODES), "--max-steps", "25", "--seed", "5",
       "--preset", "nnql")  # the paper's nnQL collides, so collisions show
WORLD_ENTITIES = ("world/grid", "world/collisions", "events",
                  *(f"world/agents/{i}/{part}" for i in range(AGENTS)
                    for part in (*PER_TICK_PARTS, GOAL, START)))
PER_TICK = ("world/collisions",
            *(f"world/agents/{i}/{part}" for i in range(AGENTS) for part in PER_TICK_PARTS))


class Recording:
    """A loaded .rrd: every chunk's rows by entity path, and the stores the file holds."""

    def __init__(self, path: Path) -> None:
        reader = rr.chunk.RrdReader(path)
        self.recordings = reader.recordings()
        self.blueprints = reader.blueprints()
        self.temporal: dict[str, list] = defaultdict(list)
        self.static: set[str] = set()
        for chunk in reader.stream():
            entity = chunk.entity_path.lstrip("/")
            if chunk.is_static:
                self.static.add(entity)
            else:
                self.temporal[entity].append(chunk.to_record_batch())

    @property
    def entities(self) -> set[str]:
        return self.static | set(self.temporal)

    def column(self, entity: str, name: str) -> list:
        return [v for batch in self.temporal[entity] for v in batch.column(name).to_pylist()]

    def by_time(self, entity: str, name: str, timeline: str = "tick") -> dict:
        """A column's values by the timeline's value of their rows."""
        return dict(zip(self.column(entity, timeline), self.column(entity, name)))

    def scalars(self, entity: str) -> dict[int, tuple[int, float]]:
        """episode -> (tick, value) of a per-episode series."""
        episodes = self.column(entity, "episode")
        ticks = self.column(entity, "tick")
        values = [v[0] for v in self.column(entity, "Scalars:scalars")]
        return {e: (t, v) for e, t, v in zip(episodes, ticks, values)}

    def rows(self, entity: str) -> int:
        return sum(batch.num_rows for batch in self.temporal[entity])

    def agents(self, part: str, name: str, timeline: str = "tick") -> dict:
        """A part of every agent (``recording.agent_entities``: each agent, or each group, an
        entity of its own) by the timeline's value: the entities' values, agent by agent, as
        one list, as one entity of all agents would hold them (its last row per value)."""
        held = [entity for entity in self.temporal
                if entity.startswith("world/agents/") and entity.endswith(f"/{part}")]
        whole: dict = defaultdict(list)
        for entity in sorted(held, key=lambda e: int(e.split("/")[2].removeprefix("group-"))):
            for key, values in self.by_time(entity, name, timeline).items():
                whole[key].extend(values or [])
        return dict(whole)


def verify(path: Path) -> None:
    result = subprocess.run([*rerun_binary(), "rrd", "verify", str(path)], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr


@pytest.fixture(scope="module")
def distributed(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "dist"
    result = run_swarm(out, *RUN, "--run-id", "rec-dist")
    assert result.returncode == 0, result.stderr
    return out, Recording(out / "run.rrd")


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    """An in-process run that also streams to a viewer (a gRPC server saving what it receives)."""
    base = tmp_path_factory.mktemp("rec")
    port = free_port()
    received = base / "received.rrd"
    server = subprocess.Popen([*rerun_binary(), "--serve-grpc", "--port", str(port),
                               "--save", str(received)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        out = base / "local"
        result = run_swarm(out, *RUN, "--run-id", "rec-local", "--in-process",
                           "--rerun-connect", f"rerun+http://127.0.0.1:{port}/proxy")
        assert result.returncode == 0, result.stderr
        time.sleep(0.5)
    finally:
        server.terminate()
        server.wait(10)
    return out, Recording(out / "run.rrd"), received


@pytest.fixture(params=["distributed", "in_process"])
def run(request):
    out, recording, *_ = request.getfixturevalue(request.param)
    return request.param, out, recording


@pytest.mark.full
def test_one_verified_recording_with_the_run_id_and_a_blueprint(run):
    mode, out, recording = run
    verify(out / "run.rrd")
    run_id = {"distributed": "rec-dist", "in_process": "rec-local"}[mode]
    assert [s.recording_id for s in recording.recordings] == [run_id]
    assert len(recording.blueprints) == 1
    assert not (out / PARTS_DIR).exists()  # merged, parts removed


@pytest.mark.full
def test_the_world_is_there_every_tick(run):
    _, out, recording = run
    assert set(WORLD_ENTITIES) <= recording.entities
    ticks = int(read_episodes(out / "episodes.csv")[-1]["end_tick"]) + 1
    for entity in PER_TICK:
        assert sorted(recording.column(entity, "tick")) == list(range(ticks)), entity
    assert all(recording.rows(f"world/agents/{i}/goal") == EPISODES for i in range(AGENTS))


@pytest.mark.full
def test_positions_and_trails_are_the_worlds(run):
    _, out, recording = run
    config = SwarmConfig.from_json((out / "config.json").read_text())
    cells = recording.agents(DISC, "Points2D:positions")
    trails = recording.agents(TRAIL, "LineStrips2D:strips")
    first_tick = 0
    for row in read_episodes(out / "episodes.csv"):
        starts = swarm_episode(config.seed, int(row["episode"]), config.width, config.height,
                               config.n_agents).starts
        assert np.array_equal(np.array(cells[first_tick]), starts), row["episode"]
        first_tick = int(row["end_tick"]) + 1
    for tick, strips in trails.items():
        assert np.array_equal(np.array([strip[-1] for strip in strips]), np.array(cells[tick]))


def test_starts_stuck_agents_and_the_caption_are_the_worlds(run):
    """Each episode's starts; at its end a ring around every agent not on its goal (as many as
    episodes.csv says did not arrive, each where one of them stands), none while it goes; and on
    every tick a caption naming its episode."""
    _, out, recording = run
    config = SwarmConfig.from_json((out / "config.json").read_text())
    cells = recording.agents(DISC, "Points2D:positions")
    starts = recording.agents(START, "Points2D:positions", "episode")
    stuck = defaultdict(list)
    for tick, rings in zip(recording.column("world/stuck", "tick"),
                           recording.column("world/stuck", "LineStrips2D:strips")):
        stuck[tick].append([np.mean(ring[:-1], axis=0).round(3).tolist() for ring in rings or []])
    first_tick, ended_short = 0, 0
    for row in read_episodes(out / "episodes.csv"):
        episode, end = int(row["episode"]), int(row["end_tick"])
        expected = swarm_episode(config.seed, episode, config.width, config.height,
                                 config.n_agents).starts
        assert np.array_equal(np.array(starts[episode]), expected)
        assert stuck[first_tick][0] == []  # cleared as the episode starts
        ringed = stuck[end][-1]
        assert len(ringed) == config.n_agents - int(row["arrived"]), episode
        goals = swarm_episode(config.seed, episode, config.width, config.height,
                              config.n_agents).goals.tolist()
        short = {tuple(cell) for cell, goal in zip(cells[end], goals) if cell != goal}
        assert {tuple(cell) for cell in ringed} == short, episode  # the end tick moves nobody
        ended_short += len(ringed)
        first_tick = end + 1
    assert ended_short > 0, "no agent ended short: the rings were not tested"
    episodes = recording.by_time("world/agents/0/disc", "episode")
    for tick, labels in recording.by_time("world/caption", "Points2D:labels").items():
        assert labels[0].startswith(f"episode {episodes[tick]}, ") and f"(tick {tick})" in labels[0]


def smoothed(values):
    """The exponential moving average the steps plot draws over the ratios (weight 0.1)."""
    average = None
    for value in values:
        average = value if average is None else 0.9 * average + 0.1 * value
        yield average


@pytest.mark.full
def test_metrics_match_episodes_csv(run):
    _, out, recording = run
    rows = read_episodes(out / "episodes.csv")
    assert set(METRICS) <= recording.entities
    expected = {
        "metrics/collisions/per_episode": [float(r["collisions"]) for r in rows],
        "metrics/collisions/cumulative": list(np.cumsum([float(r["collisions"]) for r in rows])),
        "metrics/steps/episode": [float(r["steps"]) for r in rows],
        "metrics/steps/per_agent": [int(r["agent_steps"]) / AGENTS for r in rows],
        "metrics/steps/shortest_per_agent": [int(r["shortest_sum"]) / AGENTS for r in rows],
        "metrics/arrived": [float(r["arrived"]) for r in rows],
        "metrics/arrived_share": [int(r["arrived"]) / AGENTS for r in rows],
        "metrics/steps/over_shortest": [int(r["agent_steps"]) / int(r["shortest_sum"])
                                        for r in rows],
        "metrics/steps/smoothed": list(smoothed([int(r["agent_steps"]) / int(r["shortest_sum"])
                                                 for r in rows])),
        "metrics/reward_sum": [float(r["reward_sum"]) for r in rows],
        "metrics/missed_intents": [float(r["missed_intents"]) for r in rows],
    }
    for entity, values in expected.items():
        logged = recording.scalars(entity)
        assert sorted(logged) == list(range(EPISODES)), entity
        assert [logged[e][1] for e in range(EPISODES)] == pytest.approx(values), entity
        assert [logged[e][0] for e in range(EPISODES)] == [int(r["end_tick"]) for r in rows]
    assert all(v > 0 for _, v in recording.scalars("metrics/ticks_per_s").values())
    assert sum(int(r["collisions"]) for r in rows) > 0  # the run did show collisions
    assert recording.rows("world/collisions") > 0


def test_a_timed_brain_counts_only_the_asked_neighbours_that_did_not_answer():
    """The intents an agent decides with may hold arrived neighbours it never asked (the meet
    rule): they are not answers, and they make no asked neighbour answered."""
    brain = TimedBrain(3, SwarmConfig(n_agents=6))
    obs = Observation(run="run", tick=9, sender=WORLD_SENDER, agent=3, episode=0, step=9,
                      position=(4, 4), goal=(0, 0),
                      neighbours=pack_neighbours([(0, 4, 5), (1, 5, 4), (2, 3, 4)]),
                      rank=0, reward_ds=0.0, reward_ca=0.0, collided=False, arrived=False,
                      episode_end=False, parked=pack_ids([2]))
    brain.prepare(obs)
    assert brain.neighbours_to_ask(obs, [0, 1]) == [0, 1]
    brain.act(obs, {0: STAY, 2: STAY})  # 1 did not answer; 2 has arrived
    latencies, unanswered = brain.take_timings()
    assert len(latencies) == 1 and unanswered == 1


@pytest.mark.full
def test_every_agent_logged_what_it_learned_every_tenth_episode_and_the_last(run):
    mode, out, recording = run
    logged = [e for e in range(EPISODES) if logs_heat_maps(e, EPISODES)]
    assert logged == [0, EPISODES - 1]
    for agent in range(AGENTS):
        for table in TABLES:
            for part in ("value", "policy", "stay", "note"):
                entity = f"agents/{agent}/{table}/{part}"
                assert sorted(recording.column(entity, "episode")) == logged, entity
        if mode == "distributed":  # the negotiation wait exists only over the wire
            latency = recording.scalars(f"metrics/negotiation/latency_ms/{agent}")
            assert sorted(latency) == list(range(EPISODES))
            assert all(0 < v < 2000 for _, v in latency.values())
    # the last heat map is the picture of the agent's checkpointed table
    agent = 3
    q_ds = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", agent), ())["q_ds"]
    batches = recording.temporal[f"agents/{agent}/q_ds/value"]
    last = max(((b, i) for b in batches for i in range(b.num_rows)),
               key=lambda bi: bi[0].column("episode")[bi[1]].as_py())
    buffer = np.array(last[0].column("Image:buffer")[last[1]].as_py()[0], dtype=np.uint8)
    config = SwarmConfig.from_json((out / "config.json").read_text())
    picture = table_picture(q_ds, config.optimistic, learnable_bound("q_ds", config))
    assert np.array_equal(buffer.reshape(21, 21, 3), picture["image"])


@pytest.mark.full
def test_the_negotiation_is_logged_as_the_agents_ask(run):
    """Each tick's arrows are the queries the brains make, from the logged cells and goals."""
    _, out, recording = run
    config = SwarmConfig.from_json((out / "config.json").read_text())
    rows = read_episodes(out / "episodes.csv")
    end_ticks = {int(r["end_tick"]) for r in rows}
    cells = recording.agents(DISC, "Points2D:positions")
    episode_of = recording.by_time("world/agents/0/disc", "episode")
    arrows = recording.agents(WAITS, "Arrows2D:origins")
    total = 0
    for tick, logged in arrows.items():
        positions = np.array(cells[tick], dtype=np.int64)
        goals = swarm_episode(config.seed, episode_of[tick], config.width, config.height,
                              config.n_agents).goals
        arrived = np.all(positions == goals, axis=1)
        expected = [] if tick in end_ticks else negotiation_pairs(
            config, positions[None], arrived[None], np.array([tick]))[1].tolist()
        assert len(logged or []) == len(expected), tick
        total += len(expected)
    assert total > 0


@pytest.mark.full
@pytest.mark.filterwarnings("ignore:RRD file has no footer")  # the server was stopped, not closed
def test_a_grid_with_walls_shows_them_and_nobody_ever_stands_on_one(tmp_path):
    out = tmp_path / "walls"
    result = run_swarm(out, "--agents", "6", "--episodes", "3", "--max-steps", "30", "--grid",
                       "16x16", "--obstacle-density", "0.25", "--in-process")
    assert result.returncode == 0, result.stderr
    verify(out / "run.rrd")
    config = SwarmConfig.from_json((out / "config.json").read_text())
    walls = {tuple(cell) for cell in config.walls().tolist()}
    assert len(walls) == 64
    reader = rr.chunk.RrdReader(out / "run.rrd")
    logged = [chunk.to_record_batch().column("Boxes2D:centers").to_pylist()
              for chunk in reader.stream() if chunk.entity_path.lstrip("/") == "world/walls"]
    assert [{tuple(map(round, c)) for c in batch[0]} for batch in logged] == [walls]
    # one half-size per wall: the viewer draws one box per half-size, not one per centre
    sizes = [chunk.to_record_batch().column("Boxes2D:half_sizes").to_pylist()[0]
             for chunk in rr.chunk.RrdReader(out / "run.rrd").stream()
             if chunk.entity_path.lstrip("/") == "world/walls"]
    assert [len(batch) for batch in sizes] == [len(walls)]
    recording = Recording(out / "run.rrd")
    cells = {tuple(map(round, cell)) for tick in recording.agents(DISC, "Points2D:positions")
             .values() for cell in tick}
    assert cells and not cells & walls
    # the default preset shares one table: only agent 0 logs it, once for all; its Q_CA learns
    # nothing (recording.shown), and nobody logs it
    assert config.shared
    assert "agents/0/q_ds/table" in recording.entities
    assert not {e for e in recording.entities if "q_ca" in e}
    assert not {e for e in recording.entities if e.startswith("agents/1/")}


@pytest.mark.full
def test_streaming_to_a_viewer_sends_the_same_recording(in_process):
    out, recording, received = in_process
    streamed = Recording(received)
    assert [s.recording_id for s in streamed.recordings] == ["rec-local"]
    assert set(WORLD_ENTITIES) | set(METRICS) <= streamed.entities
    assert {f"agents/{i}/q_ca/value" for i in range(AGENTS)} <= streamed.entities
    assert streamed.scalars("metrics/reward_sum") == recording.scalars("metrics/reward_sum")


@pytest.mark.full
def test_ctrl_c_still_leaves_a_loadable_recording(tmp_path):
    out = tmp_path / "stopped"
    swarm = start_swarm(out, "--agents", "4", "--episodes", "1000", "--max-steps", "20")
    try:
        deadline = time.monotonic() + 90
        while not ((out / "episodes.csv").exists() and read_episodes(out / "episodes.csv")):
            assert time.monotonic() < deadline, "no episode finished in time"
            time.sleep(0.2)
        os.killpg(swarm.pid, signal.SIGINT)
        swarm.wait(timeout=30)
        assert swarm.returncode == 130
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    verify(out / "run.rrd")
    assert not (out / PARTS_DIR).exists()
    recording = Recording(out / "run.rrd")
    rows = read_episodes(out / "episodes.csv")
    logged = recording.scalars("metrics/collisions/per_episode")
    assert [logged[e][1] for e in range(len(rows))] == [float(r["collisions"]) for r in rows]
    # the default preset's destination seeking reads the known map: its Q_DS is a table
    assert {"world/agents/0/disc", "agents/0/q_ds/table"} <= recording.entities


@pytest.mark.full
@pytest.mark.parametrize("killed", ["world", "everything", "everything, rows behind"])
def test_a_run_killed_outright_and_resumed_records_every_episode(tmp_path, killed):
    """``kill -9`` of the world, or of every process at once: the resumed run's ``run.rrd``
    holds every episode and every tick exactly once, though the stopped run's processes had
    recorded past the resume point (the world sends an episode to its recording before its row,
    and each tick as it closes). ``rows behind``: the world's rows lag its recording by ten
    episodes, as when the world's main thread, which writes them, fell behind under load while
    the agents (learning apart, so nothing holds them back) checkpointed on: the case that
    load once made, made here every time."""
    from collections import Counter

    from tests.swarm_helpers import find_process, stops_within, wait_for_rows

    out, episodes = tmp_path / "killed", 120
    # a run id of its own: find_process below must not find another test's world
    run_id = "killed-" + "-".join(killed.replace(",", "").split())
    preset = ["--preset", "nnql"] if killed.endswith("behind") else []
    swarm = start_swarm(out, "--agents", "2", "--grid", "5x5", "--max-steps", "8", "--episodes",
                        str(episodes), "--seed", "2", "--run-id", run_id, *preset)
    try:
        wait_for_rows(out / "episodes.csv", 40, 120, swarm)
        if killed == "world":
            [world] = find_process(f"nnql-world {run_id}")
            os.kill(world, signal.SIGKILL)
        else:
            os.killpg(swarm.pid, signal.SIGKILL)
        stops_within(swarm, 10)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    if killed.endswith("behind"):
        lines = (out / "episodes.csv").read_text().splitlines(keepends=True)
        assert len(lines) >= 41
        (out / "episodes.csv").write_text("".join(lines[:31]))  # the header and episodes 0-29
    resumed = run_swarm(out, "--resume")
    assert resumed.returncode == 0, resumed.stderr
    assert not (out / PARTS_DIR).exists()
    verify(out / "run.rrd")
    recording = Recording(out / "run.rrd")
    assert [s.recording_id for s in recording.recordings] == [run_id]
    logged = Counter(recording.column("metrics/collisions/per_episode", "episode"))
    assert sorted(logged) == list(range(episodes))
    assert set(logged.values()) == {1}, resumed.stderr
    ticks = Counter(recording.column("world/agents/0/disc", "tick"))
    assert set(ticks.values()) == {1}, resumed.stderr
    rows = read_episodes(out / "episodes.csv")
    assert sorted(ticks) == list(range(int(rows[-1]["end_tick"]) + 1))


@pytest.mark.full
def test_a_recording_cut_at_a_tick_keeps_every_row_before_it_and_none_after(distributed,
                                                                            tmp_path):
    """``recording.merge.cut_at``, as a resume runs it: the recording keeps its id and its static
    data, and of every timed entity exactly its rows before the tick; a cut at tick 0 (a run
    that starts afresh) leaves no recording."""
    import shutil

    from nnql_swarm.recording.merge import cut_at

    out, whole = distributed
    folder = tmp_path / "cut"
    folder.mkdir()
    shutil.copy(out / "run.rrd", folder / "run.rrd")
    ticks = sorted(set(whole.column("world/agents/0/disc", "tick")))
    tick = ticks[len(ticks) // 2]
    cut_at(folder, tick, "rec-dist")
    verify(folder / "run.rrd")
    kept = Recording(folder / "run.rrd")
    assert [s.recording_id for s in kept.recordings] == ["rec-dist"]
    assert kept.static == whole.static
    timed = [e for e, batches in whole.temporal.items()
             if all("tick" in batch.schema.names for batch in batches)]
    assert len(timed) > 20
    for entity in timed:
        before = sorted(t for t in whole.column(entity, "tick") if t < tick)
        assert sorted(kept.column(entity, "tick")) == before, entity
    cut_at(folder, 0, "rec-dist")
    assert not (folder / "run.rrd").exists()


def test_a_bad_viewer_url_is_a_one_line_usage_error(tmp_path):
    result = run_swarm(tmp_path / "bad", "--rerun-connect", "http://nowhere", timeout=60)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "viewer URL" in lines[0], result.stderr


def test_heat_map_pixels_are_egocentric_offsets():
    q = np.zeros((441, 5))
    q[offset_state(3, -2), RIGHT] = 2.0  # goal 3 right, 2 up: move right
    q[offset_state(-1, 0), UP] = 1.0
    q[offset_state(0, 4), STAY] = 0.5
    q[offset_state(5, 5), UP] = 7.0  # above the bound: not learnable, still optimistic
    picture = table_picture(q, 0.0, bound=2.0)
    assert picture["visited"].sum() == 4
    row, col = 10 - 2, 10 + 3  # row = dy + 10, column = dx + 10
    assert picture["best"][row, col] == RIGHT and picture["value"][row, col] == 2.0
    assert picture["best"][10, 9] == UP
    assert tuple(picture["image"][row, col]) == (253, 231, 37)  # the bound: brightest
    assert tuple(picture["image"][15, 15]) == OPTIMISTIC
    assert tuple(picture["image"][0, 0]) == UNVISITED
    # a fixed scale: the same value, the same colour, whatever else the table holds
    alone = np.zeros((441, 5))
    alone[offset_state(0, 4), STAY] = 0.5
    assert tuple(table_picture(alone, 0.0, bound=2.0)["image"][14, 10]) == \
        tuple(picture["image"][14, 10])


def test_experiment_curves_go_into_a_recording(tmp_path):
    from nnql_swarm.experiment.paper import PaperSettings, RunSpec, run_batch

    specs = [RunSpec(algo, k, seed) for algo in ("ql", "nnql") for k in (2, 5) for seed in (0, 1)]
    metrics = run_batch(specs, PaperSettings(episodes=6, max_steps=30))
    path = tmp_path / "experiment.rrd"
    log_experiment(specs, metrics, path)
    verify(path)
    recording = Recording(path)
    assert len(recording.blueprints) == 1
    curve = recording.column("experiment/collisions/nnql/k5", "Scalars:scalars")
    assert [v[0] for v in curve] == pytest.approx(metrics.collisions[[6, 7]].mean(axis=0))
    cumulative = recording.column("experiment/cumulative_collisions/ql/k2", "Scalars:scalars")
    assert cumulative[-1][0] == pytest.approx(metrics.collisions[[0, 1]].sum(axis=1).mean())
    extra = recording.column("experiment/extra_steps/ql/k5", "Scalars:scalars")
    assert [v[0] for v in extra] == pytest.approx(
        (metrics.steps[[2, 3]] - metrics.shortest[[2, 3]]).mean(axis=0))


def test_processes_that_do_not_record_never_load_rerun():
    """An agent with recording off, or past the recorded few, keeps Rerun's 60 MiB out."""
    probe = (
        "import sys\n"
        "from nnql_swarm.protocol.config import SwarmConfig\n"
        "from nnql_swarm.recording.loggers import RECORDED_AGENTS, open_agent_viz\n"
        "from nnql_swarm.recording.sinks import RecordingPlan\n"
        "config = SwarmConfig(n_agents=16)\n"
        "assert open_agent_viz(None, 0, config) == (None, None, None)\n"
        "assert 'rerun' not in sys.modules, 'open_agent_viz(None) loaded rerun'\n"
        "plan = RecordingPlan.to_files(config, sys.argv[1])\n"
        "assert open_agent_viz(plan, RECORDED_AGENTS, config) == (None, None, None)\n"
        "assert 'rerun' not in sys.modules, 'an agent past the recorded few loaded rerun'\n"
        "print('ok')\n"
    )
    done = subprocess.run([os.sys.executable, "-c", probe, "/tmp/unused-recording"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr


@pytest.mark.full
def test_the_known_map_path_and_q_ds_table_are_the_learners_and_ql_is_the_reference(tmp_path):
    """The chosen agent's known map, replayed by the recording, ends as the walls its learner
    kept (its checkpoint); each tick's planned path runs from its cell to its goal around the
    walls it knew; the Q_DS table is the checkpointed table's; the reference curves are those of
    a run of the paper's QL on the same settings."""
    options = ("--agents", "6", "--episodes", "12", "--max-steps", "60", "--grid", "21x21",
               "--obstacle-density", "0.2", "--seed", "4", "--in-process")
    out = tmp_path / "map"
    result = run_swarm(out, *options, "--map-agent", "2", "--reference")
    assert result.returncode == 0, result.stderr
    verify(out / "run.rrd")
    config = SwarmConfig.from_json((out / "config.json").read_text())
    assert config.ds_state == "progress" and config.shared  # the default preset
    recording = Recording(out / "run.rrd")
    walls = {tuple(cell) for cell in config.walls().tolist()}
    known_at = recording.by_time("known_map/walls/known", "Boxes2D:centers")
    unseen_at = recording.by_time("known_map/walls/unseen", "Boxes2D:centers")
    assert len(known_at) > 1 and known_at.keys() == unseen_at.keys()  # it learned as it went
    cells_of = lambda boxes: {tuple(map(round, c)) for c in boxes or []}  # noqa: E731
    sizes = [len(cells_of(known_at[t])) for t in sorted(known_at)]
    assert sizes == sorted(sizes) and sizes[0] < len(walls)
    for tick in known_at:
        assert cells_of(known_at[tick]) | cells_of(unseen_at[tick]) == walls
        assert not cells_of(known_at[tick]) & cells_of(unseen_at[tick])
    kept = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", 2), ())
    learner_known = {(c % config.width, c // config.width) for c in kept["known_walls"].tolist()}
    assert cells_of(known_at[max(known_at)]) == learner_known
    # every planned path: from the agent's cell to its goal, step by step, off the known walls
    ticks = recording.column("known_map/path", "tick")
    paths = recording.column("known_map/path", "LineStrips2D:strips")
    here = recording.by_time("known_map/agent", "Points2D:positions")
    goals = recording.by_time("known_map/goal", "Boxes2D:centers")
    world = recording.agents(DISC, "Points2D:positions")
    changes = sorted(known_at)
    reached = 0
    for tick, strips in zip(ticks, paths):
        path = [tuple(map(round, c)) for c in strips[0]]
        assert path[0] == tuple(map(round, here[tick][0])) == tuple(map(round, world[tick][2]))
        known = cells_of(known_at[max(t for t in changes if t <= tick)])
        assert not set(path) & known
        assert all(abs(ax - bx) + abs(ay - by) == 1 for (ax, ay), (bx, by) in zip(path, path[1:]))
        if len(path) > 1:
            assert path[-1] == tuple(map(round, goals[tick][0]))
            reached += 1
    assert reached > len(ticks) / 2
    # Q_DS: a table of its 16 progress states, the checkpointed table's at the run's end
    q_ds = read_fields(agent_checkpoint.checkpoint_path(out / "checkpoints", 0), ())["q_ds"]
    texts = recording.by_time("agents/0/q_ds/table", "TextDocument:text", "episode")
    table, learned = ds_table(q_ds, "progress", config.optimistic, learnable_bound("q_ds", config))
    assert learned and table in texts[config.episodes - 1][0]
    assert table.count("\n| ") == 17  # a heading row and one row per state
    assert "agents/0/q_ds/value" not in recording.entities
    # the reference: the paper's QL on the same settings, episode for episode
    ql = tmp_path / "ql"
    assert run_swarm(ql, *options, "--preset", "ql", "--no-record").returncode == 0
    rows = read_episodes(ql / "episodes.csv")
    reference = recording.column("metrics/collisions/per_episode/paper_ql", "Scalars:scalars")
    assert [v[0] for v in reference] == [float(r["collisions"]) for r in rows]
    arrived = recording.column("metrics/arrived_share/paper_ql", "Scalars:scalars")
    assert [v[0] for v in arrived] == [int(r["arrived"]) / 6 for r in rows]


def test_a_map_agent_out_of_range_is_a_one_line_usage_error(tmp_path):
    result = run_swarm(tmp_path / "bad", "--agents", "4", "--map-agent", "4", "--in-process",
                       timeout=60)
    assert result.returncode == 2
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and "--map-agent 4 out of range 0..3" in lines[0], result.stderr


def test_agent_colours_stay_distinct_and_readable_at_128_agents():
    colours = agent_colors(128)
    assert np.array_equal(colours[:len(PALETTE)], PALETTE)
    assert len(np.unique(colours, axis=0)) == 128
    linear = colours / 255.0
    linear = np.where(linear <= 0.04045, linear / 12.92, ((linear + 0.055) / 1.055) ** 2.4)
    luminance = linear @ [0.2126, 0.7152, 0.0722]
    assert np.all(1.05 / (luminance[len(PALETTE):] + 0.05) >= 4.5)  # text on white
    for colour, apart in KEEP_APART:  # the colours added beyond the palette
        assert np.abs(colours[len(PALETTE):].astype(int) - colour).max(axis=1).min() > apart
    assert np.array_equal(agent_colors(200)[:128], colours)  # an agent keeps its colour


def steps_views(reference: bool) -> dict:
    """The learning curves' steps plots of the default run's blueprint, by name."""
    from nnql_swarm.recording.blueprint import blueprint

    def views(container):
        for item in getattr(container, "contents", None) or []:
            yield item
            yield from views(item)

    return {v.name: v for v in views(blueprint(SwarmConfig(), reference=reference).root_container)
            if getattr(v, "origin", None) == "metrics/steps"}


def test_with_the_reference_both_steps_ratios_read_on_plots_of_their_own():
    """The paper's QL's ratio (10 to 20) runs far above the run's own (1 to 4): the run's plot
    leaves it out, and a plot of both beside it takes the span of both; no span is fixed, so
    that neither is clipped."""
    from nnql_swarm.recording.blueprint import REFERENCE_STEPS

    alone, both = steps_views(False), steps_views(True)
    assert list(alone) == ["Steps / shortest, smoothed"]
    own, with_ql = (both["Steps / shortest, smoothed"],
                    both["Steps ratio: paper's QL in grey"])
    assert REFERENCE_STEPS not in own.contents and REFERENCE_STEPS in with_ql.contents
    for view in (*alone.values(), *both.values()):
        assert "ScalarAxis" not in view.properties


def test_the_known_map_shows_one_path_and_the_world_an_episodes_moves():
    """On the episode timeline the known map shows the newest planned path, not every path of
    the episode at once (a comb); the world view shows the episode's moves, waits, collisions."""
    from nnql_swarm.recording.blueprint import blueprint

    def views(container):
        for item in getattr(container, "contents", None) or []:
            yield item
            yield from views(item)

    by_origin = {getattr(v, "origin", None): v
                 for v in views(blueprint(SwarmConfig()).root_container)}
    assert not by_origin["known_map"].visualizer_overrides
    assert set(by_origin["world"].visualizer_overrides) == {
        *(f"world/agents/{i}/{part}" for i in range(8) for part in ("path", "intent", "waits")),
        "world/collisions", "world/refused", "world/pushes", "world/reached"}


def test_priority_inheritance_and_lifelong_goals_are_seen(tmp_path):
    """``--arbitration pibt --tasks lifelong``: the refused first choices and the pushes, the
    goals reached where they were and the goals moving on, the throughput and refusals curves
    (each against ``episodes.csv``), the same distributed as in-process."""
    options = ("--agents", "10", "--episodes", "3", "--max-steps", "40", "--preset", "pibt-nnql",
               "--tasks", "lifelong", "--map", "random:12x12:0.2:3")
    jams = {}
    for where, extra in (("local", ("--in-process",)), ("dist", ())):
        out = tmp_path / where
        result = run_swarm(out, *options, *extra)
        assert result.returncode == 0, result.stderr
        verify(out / "run.rrd")
        recording = Recording(out / "run.rrd")
        rows = read_episodes(out / "episodes.csv")
        assert {"world/refused", "world/pushes", "world/reached"} <= recording.entities
        throughput = recording.scalars("metrics/throughput")
        assert {e: v for e, (_, v) in throughput.items()} == {
            int(r["episode"]): float(r["throughput"]) for r in rows}
        reached = recording.column("world/reached", "Points2D:positions")
        assert sum(len(cells) for cells in reached) == sum(int(r["goals"]) for r in rows) > 0
        goals = recording.column("world/agents/0/goal", "Boxes2D:centers")
        assert len(goals) > len(rows), "the goals move on within an episode"
        refused = recording.column("world/refused", "Arrows2D:origins")
        refusals = recording.scalars("metrics/refused")
        assert sum(len(r) for r in refused) == sum(v for _, v in refusals.values()) > 0
        pushes = recording.column("world/pushes", "Arrows2D:vectors")
        assert sum(len(p) for p in pushes) > 0
        assert all(0.7 < abs(x) + abs(y) <= 0.8 + 1e-6 for p in pushes for x, y in p), \
            "a push goes to a neighbouring cell"
        assert not recording.column("world/collisions", "Points2D:positions") or all(
            len(c) == 0 for c in recording.column("world/collisions", "Points2D:positions"))
        # Where the jams were: each episode's end draws the cells waited on (none are walls),
        # each episode's start clears them.
        jams[where] = recording.by_time("world/jams", "Boxes2D:centers")
        ends = [cells for cells in jams[where].values() if cells]
        walls = {tuple(cell) for cell in
                 SwarmConfig.from_json((out / "config.json").read_text()).walls().tolist()}
        assert len(ends) == len(rows) and all(
            not walls & {tuple(map(int, cell)) for cell in cells} for cells in ends)
    assert jams["local"] == jams["dist"]


def test_each_agent_is_an_entity_of_its_own_and_from_16_in_groups(run, tmp_path):
    """A person can pick one agent: each is ``world/agents/<id>`` with its disc, trail, path,
    announced moves, waits, goal and start, each with data; from ``GROUPED_FROM`` (16) agents on,
    groups of 64 (``world/agents/group-<k>``), so that the web viewer draws them on the grid."""
    from nnql_swarm.recording.agent_entities import GROUP_SIZE, GROUPED_FROM, PER_EPISODE

    assert AGENTS < GROUPED_FROM == 16

    _, out, recording = run
    ticks = int(read_episodes(out / "episodes.csv")[-1]["end_tick"]) + 1
    for i in range(AGENTS):
        for part in PER_TICK_PARTS:
            assert recording.rows(f"world/agents/{i}/{part}") == ticks, (i, part)
        for part in PER_EPISODE:
            assert recording.rows(f"world/agents/{i}/{part}") == EPISODES, (i, part)
        assert all(len(cell) == 1 for cell in recording.column(f"world/agents/{i}/disc",
                                                               "Points2D:positions"))
    waits = sum(len(w or []) for i in range(AGENTS)
                for w in recording.column(f"world/agents/{i}/waits", "Arrows2D:origins"))
    assert waits > 0
    crowd = tmp_path / "crowd"
    result = run_swarm(crowd, "--agents", "130", "--grid", "24x24", "--episodes", "1",
                       "--max-steps", "6", "--in-process")
    assert result.returncode == 0, result.stderr
    grouped = Recording(crowd / "run.rrd")
    owners = {e.split("/")[2] for e in grouped.entities if e.startswith("world/agents/")}
    assert owners == {f"group-{k}" for k in range(3)}
    sizes = {k: {len(cells) for cells in grouped.column(f"world/agents/group-{k}/disc",
                                                        "Points2D:positions")}
             for k in range(3)}
    assert sizes == {0: {GROUP_SIZE}, 1: {GROUP_SIZE}, 2: {2}}
    cells = grouped.agents(DISC, "Points2D:positions")
    starts = swarm_episode(0, 0, 24, 24, 130).starts
    assert np.array_equal(np.array(cells[0]), starts)


def test_the_world_view_holds_few_entities_from_16_agents_on():
    """Rerun's WebGL depth offsets scale each entity's drawing a step further from the grid's
    (``recording.agent_entities.GROUPED_FROM``): from 16 agents on, a group holds 64 agents."""
    from nnql_swarm.recording.agent_entities import owners

    assert [path for path, _ in owners(15)] == [f"world/agents/{i}" for i in range(15)]
    assert [(path, agents.tolist()) for path, agents in owners(16)] == \
        [("world/agents/group-0", list(range(16)))]
    assert [len(agents) for _, agents in owners(64)] == [64]
    assert [len(agents) for _, agents in owners(130)] == [64, 64, 2]


@pytest.mark.full
def test_every_panel_has_data_distributed_and_in_process(run):
    """The blueprint's panels of a distributed run (the agents' negotiation wait among them)
    and of an in-process one, each with data (``tests/test_panels.py``: every preset)."""
    from tests.test_panels import Panels

    mode, out, _ = run
    panels = Panels(out)
    assert not {view.name: lack for view in panels.views if (lack := panels.has_data(view))}
    assert ("Negotiation wait (ms)" in {view.name for view in panels.views}) == \
        (mode == "distributed")


def test_a_copy_follows_one_agent_tick_by_tick(run, tmp_path):
    """``recording.follow``: a copy of the run up to a tick, whose world view shows every
    agent's disc and only the followed agent's parts, on the ``tick`` timeline."""
    from nnql_swarm.recording.blueprint import blueprint
    from nnql_swarm.recording.follow import follow_copy
    from tests.test_panels import included, views

    from nnql_swarm.recording.follow import curves_copy

    _, out, recording = run
    copy = Recording(follow_copy(out, tmp_path / "follow.rrd", 3, 30, since=20))
    assert len(copy.blueprints) == 1
    assert sorted(copy.column("world/agents/3/disc", "tick")) == list(range(20, 31))
    assert copy.scalars("metrics/reward_sum") == {
        e: v for e, v in recording.scalars("metrics/reward_sum").items() if v[0] <= 30}
    curves = Recording(curves_copy(out, tmp_path / "curves.rrd"))
    assert curves.scalars("metrics/reward_sum") == recording.scalars("metrics/reward_sum")
    assert not {e for e in curves.entities if e.startswith("world/")}
    assert copy.agents(DISC, "Points2D:positions")[30] == \
        recording.agents(DISC, "Points2D:positions")[30]
    config = SwarmConfig.from_json((out / "config.json").read_text())
    [world] = [v for v in views(blueprint(config, follow=3).root_container)
               if str(v.origin) == "world"]
    shown = {e for e in recording.entities if included(e, "world", list(world.contents))}
    parts = {e.rsplit("/", 1)[1] for e in shown if e.startswith("world/agents/3/")}
    assert parts == {*PER_TICK_PARTS, GOAL, START}
    assert {e for e in shown if e.startswith("world/agents/") and "/3/" not in e} == \
        {f"world/agents/{i}/disc" for i in range(AGENTS) if i != 3}
    assert "world/grid" in shown and "world/caption" in shown
