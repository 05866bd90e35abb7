"""Rerun for a run: where each process's recording goes, the viewer's blueprint, the final merge.

Every process of a run (the world, each agent, or the one in-process runner) logs into the same
recording, whose id is the run id. Sinks (a :class:`RecordingPlan`, handed to each process):

- by default each process saves its own part, ``<out>/rerun-parts/<role>.<pid>.rrd``, and the
  launcher merges the parts into ``<out>/run.rrd`` when the run ends, Ctrl-C included
  (:func:`merge_parts`; an existing ``run.rrd`` of a resumed run is merged in too; the parts are
  kept if merging fails);
- ``--rerun-spawn`` starts the native viewer, ``--rerun-connect URL`` uses a running one,
  ``--rerun-serve-web`` serves the web viewer; every process then also streams to that viewer
  (:class:`RecordingSession`).

:func:`blueprint` is the first view: the grid on the left, the metrics in the middle, each
agent's heat maps on the right. :func:`log_experiment` puts the paper experiment's learning
curves into a recording of their own.
"""

import argparse
import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import quote, urlparse

import numpy as np

from nnql_swarm.protocol.config import SwarmConfig

APP_ID = "nnql-swarm"
PARTS_DIR = "rerun-parts"
RECORDING_FILE = "run.rrd"
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090
VIEWER_START_S = 15.0
"""How long the launcher waits for a viewer it started to accept connections."""

class RecordingError(RuntimeError):
    """The recording cannot go where it was asked to (no viewer at the URL, bad URL)."""


def rerun_binary() -> list[str]:
    """The ``rerun`` command of this environment: the native binary of the ``rerun_cli`` package
    (no Python start-up), else the script next to the interpreter, else on PATH."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        native = Path(spec.origin).parent / "rerun"
        if native.is_file() and os.access(native, os.X_OK):
            return [str(native)]
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return [str(beside)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun_cli"]


def grpc_url(port: int, host: str = "127.0.0.1") -> str:
    return f"rerun+http://{host}:{port}/proxy"


def check_viewer_url(url: str) -> str:
    """A viewer URL as ``--rerun-connect`` takes it; raises ArgumentTypeError otherwise."""
    parsed = urlparse(url)
    if parsed.scheme not in ("rerun", "rerun+http", "rerun+https") or not parsed.hostname \
            or parsed.path.rstrip("/") != "/proxy":
        raise argparse.ArgumentTypeError(
            f"expected a viewer URL such as {grpc_url(DEFAULT_GRPC_PORT)}, not {url!r}")
    return url


def reachable(url: str, timeout: float = 1.0) -> bool:
    """Whether something accepts TCP connections where the viewer URL points."""
    parsed = urlparse(url)
    default = 443 if parsed.scheme == "rerun+https" else DEFAULT_GRPC_PORT
    try:
        with socket.create_connection((parsed.hostname, parsed.port or default), timeout=timeout):
            return True
    except OSError:
        return False


@dataclass(frozen=True)
class RecordingPlan:
    """Where every process of a run sends its part of the recording (picklable, for spawn)."""

    run_id: str
    parts_dir: Path | None = None  # save a part here (None: no file)
    url: str | None = None  # also stream to this viewer
    map_agent: int | None = 0  # whose known map the recording shows (recording.known_map)

    @staticmethod
    def to_files(config: SwarmConfig, out: Path) -> "RecordingPlan":
        return RecordingPlan(config.run_id, parts_dir=Path(out) / PARTS_DIR)

    @property
    def enabled(self) -> bool:
        return self.parts_dir is not None or self.url is not None

    def open(self, role: str, default_blueprint=None):
        """This process's ``rr.RecordingStream`` into the run's recording; ``role`` names its
        part file."""
        import rerun as rr

        stream = rr.RecordingStream(APP_ID, recording_id=self.run_id)
        sinks = []
        if self.parts_dir is not None:
            Path(self.parts_dir).mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(Path(self.parts_dir) / f"{role}.{os.getpid()}.rrd")))
        if self.url is not None:
            sinks.append(rr.GrpcSink(self.url))
        stream.set_sinks(*sinks, default_blueprint=default_blueprint)
        return stream


def exit_without_teardown(code: int = 0) -> None:
    """End a spawned process that has closed its recording, skipping the interpreter's teardown.

    With Rerun loaded, Python's own teardown takes about 0.5 s (more on a busy machine), which
    every process of a run pays on Ctrl-C. This exits with ``code`` after flushing the log
    handlers and standard streams.
    """
    import logging

    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def plan_of(record, config: SwarmConfig, out: Path) -> RecordingPlan | None:
    """A plan from what a launcher function was given: a plan, True (files), False/None (off)."""
    if isinstance(record, RecordingPlan):
        return record if record.enabled else None
    return RecordingPlan.to_files(config, out) if record else None


def open_world_viz(record, config: SwarmConfig, out: Path, distributed: bool = True):
    """The world's logger (``world.viz.WorldViz``) with the blueprint, or None if not recording.
    ``distributed``: the agents are processes that time their negotiation (the blueprint plots
    it)."""
    from nnql_swarm.world.metrics import read_episodes
    from nnql_swarm.world.viz import WorldViz

    plan = plan_of(record, config, out)
    if plan is None:
        return None
    episodes = Path(out) / "episodes.csv"  # a resumed run's complete episodes so far
    before = sum(int(row["collisions"]) for row in read_episodes(episodes)) \
        if episodes.exists() else 0
    return WorldViz(config, plan.open("world", blueprint(config, distributed, plan.map_agent)),
                    collisions_before=before, map_agent=plan.map_agent)


RECORDED_AGENTS = 8
"""Agents ``0 .. RECORDED_AGENTS - 1`` log their own entities (heat maps, negotiation timing);
the others log nothing and never load Rerun. The world's entities show every agent, each entity
all of them at once: a viewer slows down with hundreds of entities, and 128 agents logging their
own would give it over a thousand."""


def logs_own_heat_maps(agent: int, config: SwarmConfig) -> bool:
    """Whether a recorded agent logs its heat maps: each of them, or only agent 0 where the
    agents share one table (the same table in every copy)."""
    return agent < RECORDED_AGENTS and (agent == 0 or not config.shared)


def heat_map_agents(config: SwarmConfig) -> list[int]:
    """The agents whose heat maps the recording holds."""
    return [i for i in range(min(config.n_agents, RECORDED_AGENTS))
            if logs_own_heat_maps(i, config)]


def open_agent_viz(plan: RecordingPlan | None, agent: int, config: SwarmConfig):
    """``(brain, on_episode_end, viz)`` for an agent process; all None if not recording."""
    if plan is None or not plan.enabled:
        return None, None, None
    if agent >= RECORDED_AGENTS:
        return None, None, None
    from nnql_swarm.agent.viz import AgentViz, TimedBrain

    viz = AgentViz(agent, config, plan.open(f"agent-{agent}"),
                   heat_maps=logs_own_heat_maps(agent, config))
    return TimedBrain(agent, config), viz.on_episode_end, viz


class InProcessRecorder:
    """World and agents of the in-process runner logging into one stream."""

    def __init__(self, record, config: SwarmConfig, out: Path) -> None:
        from nnql_swarm.agent.viz import AgentViz

        self.world = open_world_viz(record, config, out, distributed=False)
        self.agents = []
        if self.world is not None:
            self.agents = [AgentViz(i, config, self.world.rec, lambda: self.world.next_tick,
                                    heat_maps=logs_own_heat_maps(i, config))
                           for i in range(min(config.n_agents, RECORDED_AGENTS))]

    def on_tick(self, world, report) -> None:
        if self.world is not None:
            self.world.log_tick(world, report)

    def on_episode_end(self, brain, episode: int) -> None:
        if brain.agent < len(self.agents):
            self.agents[brain.agent].on_episode_end(brain, episode)

    def close(self) -> None:
        for agent in self.agents:  # they share the world's stream, which the world closes
            agent.flush()
        if self.world is not None:
            self.world.close()


def blueprint(config: SwarmConfig, distributed: bool = True, map_agent: int | None = 0):
    """The first view: the world and its key | the learning curves | the heat maps.

    The viewer opens on the ``episode`` timeline, following the newest episode: the curves run
    against episodes, and the world view shows that whole episode at once (every announced move,
    every wait, every collision; agents, goals and trails as the episode left them).
    """
    import rerun.blueprint as rrb

    from nnql_swarm.world import viz as world_viz

    episode = rrb.VisibleTimeRanges(timeline="episode",
                                    start=rrb.TimeRangeBoundary.cursor_relative(seq=0),
                                    end=rrb.TimeRangeBoundary.cursor_relative(seq=0))
    world_view = rrb.Spatial2DView(
        origin="world", name="World: the episode's moves, waits and collisions",
        visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, config.width - 0.4],
                                         y_range=[-0.6, config.height - 0.4]),
        overrides={path: episode for path in (world_viz.INTENTS, world_viz.NEGOTIATION,
                                              world_viz.COLLISIONS)},
    )
    events = rrb.TextLogView(origin=world_viz.EVENTS, name="Events", columns=rrb.TextLogColumns(
        timeline_columns=[rrb.encodings.TimelineColumn("episode"),
                          rrb.encodings.TimelineColumn("tick", visible=False)],
        text_log_columns=[rrb.components.TextLogColumn("LogLevel"),
                          rrb.components.TextLogColumn("Body")]))
    key = rrb.TextDocumentView(origin=world_viz.LEGEND, name="Key")
    whole_run = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                      end=rrb.TimeRangeBoundary.infinite()))

    def plot(low: float | None = None, high: float | None = None, **view) -> rrb.TimeSeriesView:
        axis = rrb.ScalarAxis(range=(low, high)) if high is not None else None
        return rrb.TimeSeriesView(axis_x=whole_run, axis_y=axis,
                                  plot_legend=rrb.PlotLegend(corner="RightBottom"), **view)

    n = config.n_agents
    metrics = rrb.Grid(
        plot(0.0, 1.05, origin="metrics/arrived_share",
             name="Share of agents on their goal at the episode's end"),
        plot(origin="metrics/steps", name="Steps taken / shortest path (1: perfect)",
             contents=["metrics/steps/over_shortest", "metrics/steps/shortest_path",
                       "metrics/steps/paper_ql"]),
        plot(0.0, float(max(2 * n, 8)), origin="metrics/collisions/per_episode",
             name="Agents in a collision, per episode"),
        plot(origin="metrics/negotiation/awaited_per_tick", name="Intents awaited per tick"),
        plot(origin="metrics/negotiation/latency_ms", name="Negotiation wait (ms)") if distributed
        else plot(origin="metrics/steps/episode", name="Ticks per episode"),
        plot(origin="metrics/ticks_per_s", name="Ticks per second"),
        grid_columns=2, name="Learning curves (x: episode)",
    )
    from nnql_swarm.agent.viz import DS_STATE_TITLES
    from nnql_swarm.recording import known_map

    shared = config.shared

    def q_ds(i: int, whose: str):
        if config.ds_state == "goal":
            return rrb.Spatial2DView(origin=f"agents/{i}/q_ds", background=[255, 255, 255],
                                     name=f"{whose} Q_DS: goal offset")
        return rrb.TextDocumentView(origin=f"agents/{i}/q_ds/table",
                                    name=f"{whose} Q_DS {DS_STATE_TITLES[config.ds_state]}")

    heat_maps = rrb.Tabs(*[
        rrb.Vertical(
            q_ds(i, "Shared" if shared else f"Agent {i}"),
            rrb.Spatial2DView(origin=f"agents/{i}/q_ca", background=[255, 255, 255],
                              name="Shared Q_CA: neighbour offset" if shared
                              else f"Agent {i} Q_CA: neighbour offset"),
            name="shared table" if shared else f"agent {i}",
        )
        for i in heat_map_agents(config)
    ], active_tab=0, name="What the agents learned")
    learned = heat_maps
    if map_agent is not None and 0 <= map_agent < n and known_map.shows_known_map(config):
        learned = rrb.Vertical(rrb.Spatial2DView(
            origin=known_map.ROOT, background=[255, 255, 255],
            name=f"Agent {map_agent}'s known map and planned paths",
            visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, config.width - 0.4],
                                             y_range=[-0.6, config.height - 0.4]),
            overrides={known_map.PATH: episode}),  # every path it planned in the episode
            heat_maps, row_shares=[2, 3])
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(world_view, events, row_shares=[3, 1] if n < 64 else [4, 1]),
            rrb.Vertical(metrics, key, row_shares=[3, 2]),
            learned,
            column_shares=[5, 5, 3],
        ),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="episode", play_state="following", state="collapsed"),
        collapse_panels=False,
    )


def merge_parts(out: Path) -> Path | None:
    """Merge ``<out>/rerun-parts/*.rrd`` (and an existing ``run.rrd``) into ``<out>/run.rrd``.

    Returns the recording's path, or None if there was nothing to merge or merging failed (then
    the parts stay where they are, and a line on stderr says so).
    """
    out = Path(out)
    parts_dir = out / PARTS_DIR
    parts = sorted(parts_dir.glob("*.rrd")) if parts_dir.is_dir() else []
    if not parts:
        return None
    target = out / RECORDING_FILE
    inputs = ([target] if target.exists() else []) + parts
    tmp = target.with_name(target.name + ".tmp")
    result = None
    for extra in ([], ["--continue-on-error"]):
        try:
            result = subprocess.run(
                [*rerun_binary(), "rrd", "merge", *extra, *map(str, inputs), "-o", str(tmp)],
                capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.TimeoutExpired) as error:
            print(f"rerun: merging the recording failed ({error}); the parts are in {parts_dir}",
                  file=sys.stderr)
            return None
        if result.returncode == 0:
            break
    if result.returncode != 0:
        tmp.unlink(missing_ok=True)
        reason = result.stderr.strip().splitlines()[-1:] or ["unknown error"]
        print(f"rerun: merging the recording failed ({reason[0]}); the parts are in {parts_dir}",
              file=sys.stderr)
        return None
    os.replace(tmp, target)
    if extra:
        print(f"rerun: some parts were damaged; merged what was readable into {target}, "
              f"kept the parts in {parts_dir}", file=sys.stderr)
        return target
    for part in parts:
        part.unlink()
    try:
        parts_dir.rmdir()
    except OSError:
        pass
    return target


class RecordingSession:
    """The launcher's side of the recording: viewer start-up, the plan for each process, merge."""

    def __init__(self, plan: RecordingPlan | None, out: Path,
                 server: subprocess.Popen | None = None, web_url: str | None = None) -> None:
        self.plan = plan
        self.out = Path(out)
        self.server = server
        self.web_url = web_url

    @staticmethod
    def start(args, config: SwarmConfig, out: Path) -> "RecordingSession":
        """From the launcher's Rerun options. A viewer that cannot be reached or started costs a
        warning on stderr: the run goes on, recording to file (unless ``--no-record``)."""
        parts = None if args.no_record else Path(out) / PARTS_DIR
        url, server, web_url = None, None, None
        if args.rerun_connect:
            url = args.rerun_connect
            if not reachable(url):
                print(f"rerun: no viewer answers at {url}; not streaming to it", file=sys.stderr)
                url = None
        elif args.rerun_spawn:
            try:
                url = spawn_viewer(args.rerun_port)
            except RecordingError as error:
                print(f"rerun: {error}; not streaming to a viewer", file=sys.stderr)
        elif args.rerun_serve_web:
            try:
                server, url, web_url = serve_web(args.rerun_port, args.rerun_web_port)
            except RecordingError as error:
                print(f"rerun: {error}; not serving the web viewer", file=sys.stderr)
        plan = RecordingPlan(config.run_id, parts, url, getattr(args, "map_agent", 0))
        return RecordingSession(plan if plan.enabled else None, out, server, web_url)

    @staticmethod
    def files_only(record: bool, config: SwarmConfig, out: Path) -> "RecordingSession":
        """Parts saved under ``out`` and merged at the end (``record``), or nothing."""
        return RecordingSession(RecordingPlan.to_files(config, out) if record else None, out)

    def finish(self, wait_for_viewers: bool = True) -> Path | None:
        """Merge the parts into ``run.rrd``; keep serving the web viewer until Ctrl-C if asked."""
        merged = merge_parts(self.out) if self.plan and self.plan.parts_dir else None
        if self.server is not None:
            previous = {s: signal.signal(s, _stop_waiting) for s in (signal.SIGINT, signal.SIGTERM)}
            try:
                if wait_for_viewers and self.server.poll() is None:
                    print(f"rerun: still serving the run at {self.web_url} ; press Ctrl-C to stop",
                          file=sys.stderr)
                    self.server.wait()
            except _StopWaiting:
                pass
            finally:
                for s, handler in previous.items():
                    signal.signal(s, handler)
                stop_process(self.server)
        return merged


class _StopWaiting(Exception):
    """Ctrl-C or SIGTERM while the launcher keeps the web viewer up after the run."""


def _stop_waiting(*_signal) -> None:
    raise _StopWaiting


def wait_until_reachable(url: str, timeout: float = VIEWER_START_S) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if reachable(url, timeout=0.5):
            return True
        time.sleep(0.2)
    return False


def spawn_viewer(port: int) -> str:
    """Start the native viewer on ``port`` (or use the one already there); returns its URL.

    The viewer is detached (its own session): it stays open after the run and Ctrl-C.
    """
    url = grpc_url(port)
    if reachable(url):
        return url
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY")
                                                 or os.environ.get("WAYLAND_DISPLAY")):
        raise RecordingError("no display for the native viewer (DISPLAY and WAYLAND_DISPLAY are "
                             "unset); --rerun-serve-web serves a web viewer instead")
    viewer = subprocess.Popen([*rerun_binary(), "--port", str(port), "--expect-data-soon"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    deadline = time.monotonic() + VIEWER_START_S
    while time.monotonic() < deadline:
        if viewer.poll() is not None:
            raise RecordingError(f"the viewer exited at start-up (exit code {viewer.returncode})")
        if reachable(url, timeout=0.5):
            time.sleep(0.5)  # a viewer that cannot open its window listens briefly, then exits
            if viewer.poll() is None:
                return url
        time.sleep(0.2)
    raise RecordingError(f"the viewer did not answer on port {port} within {VIEWER_START_S:.0f} s")


def serve_web(grpc_port: int, web_port: int) -> tuple[subprocess.Popen, str, str]:
    """Start ``rerun --serve-web`` (gRPC proxy + web viewer on every interface); print its URL."""
    server = subprocess.Popen(
        [*rerun_binary(), "--serve-web", "--port", str(grpc_port), "--web-viewer-port",
         str(web_port)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    url = grpc_url(grpc_port)
    if not wait_until_reachable(url):
        stop_process(server)
        raise RecordingError(f"rerun --serve-web did not start on ports {grpc_port}/{web_port}")
    host = public_host()
    web_url = f"http://{host}:{web_port}/?url={quote(grpc_url(grpc_port, host), safe='')}"
    print(f"rerun: web viewer at {web_url}", file=sys.stderr)
    return server, url, web_url


def public_host() -> str:
    """This machine's address as another machine would reach it (the outgoing interface's IP)."""
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
            probe.connect(("8.8.8.8", 53))  # UDP: no packet is sent, this only picks a route
            address = probe.getsockname()[0]
        if not address.startswith("127."):
            return address
    except OSError:
        pass
    return socket.gethostname() or "localhost"


def stop_process(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.terminate()
        try:
            process.wait(timeout=3)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


def log_experiment(specs, metrics, target, *, recording_id: str = "experiment"):
    """Log the paper experiment's learning curves, averaged over seeds, on the ``episode`` timeline.

    ``specs`` are ``experiment.paper.RunSpec`` (``algo``, ``random_step``, ``seed``); ``metrics`` is the
    matching ``experiment.paper.EpisodeMetrics`` (arrays ``(runs, episodes)``: ``steps``,
    ``collisions``, ``reward_ds``, ``reward_ca``, ``shortest``, ``arrived``). ``target`` is a path
    (a new ``.rrd`` file with its own blueprint is written there), or an open
    ``rr.RecordingStream``. Entities: ``experiment/<metric>/<algo>/k<k>`` for metric in
    ``collisions``, ``cumulative_collisions``, ``steps``, ``extra_steps`` (steps - shortest),
    ``reward_sum``, ``arrived``; one ``send_columns`` call each.
    """
    import rerun as rr

    from nnql_swarm.world.viz import close_stream

    groups: dict[tuple[str, int], list[int]] = {}
    for row, spec in enumerate(specs):
        groups.setdefault((spec.algo, int(spec.random_step)), []).append(row)
    if isinstance(target, rr.RecordingStream):
        stream, own = target, False
    else:
        stream, own = rr.RecordingStream(APP_ID, recording_id=recording_id), True
        stream.set_sinks(rr.FileSink(str(target)), default_blueprint=experiment_blueprint())
    curves = {
        "collisions": np.asarray(metrics.collisions, dtype=float),
        "cumulative_collisions": np.cumsum(np.asarray(metrics.collisions, dtype=float), axis=1),
        "steps": np.asarray(metrics.steps, dtype=float),
        "extra_steps": np.asarray(metrics.steps, dtype=float) - np.asarray(metrics.shortest),
        "reward_sum": np.asarray(metrics.reward_ds) + np.asarray(metrics.reward_ca),
        "arrived": np.asarray(metrics.arrived, dtype=float),
    }
    episodes = np.arange(curves["steps"].shape[1])
    for (algo, k), rows in sorted(groups.items()):
        for name, values in curves.items():
            path = f"experiment/{name}/{algo}/k{k}"
            stream.log(path, rr.SeriesLines(names=f"{algo} k={k} ({len(rows)} seeds)",
                                            colors=[_series_color(algo, k)]), static=True)
            stream.send_columns(path, [rr.TimeColumn("episode", sequence=episodes)],
                                rr.Scalars.columns(scalars=values[rows].mean(axis=0)))
    if own:
        close_stream(stream)
        return None
    return stream


def log_swarm_curves(curves: dict[str, dict[str, np.ndarray]], path: Path,
                     recording_id: str = "swarm-experiment") -> None:
    """The swarm experiment's learning curves (``experiment.swarm.curves``) into a new ``.rrd``:
    ``swarm/<metric>/<variant>`` on the ``episode`` timeline, one plot per metric."""
    import rerun as rr
    import rerun.blueprint as rrb

    from nnql_swarm.world.viz import close_stream

    stream = rr.RecordingStream(APP_ID, recording_id=recording_id)
    blueprint = rrb.Blueprint(rrb.Grid(*(rrb.TimeSeriesView(origin=f"swarm/{metric}", name=metric)
                                         for metric in curves), grid_columns=len(curves)))
    stream.set_sinks(rr.FileSink(str(path)), default_blueprint=blueprint)
    for metric, by_variant in curves.items():
        for variant, values in by_variant.items():
            entity = f"swarm/{metric}/{variant}"
            stream.log(entity, rr.SeriesLines(names=variant), static=True)
            stream.send_columns(entity, [rr.TimeColumn("episode", sequence=np.arange(values.size))],
                                rr.Scalars.columns(scalars=values))
    close_stream(stream)


_ALGO_COLORS = {"ql": (230, 120, 40), "nnql": (40, 140, 230), "nnql-dir": (60, 180, 90)}


def _series_color(algo: str, k: int) -> tuple[int, int, int]:
    """QL in oranges, nnQL in blues; larger k (less exploration) darker."""
    base = np.array(_ALGO_COLORS.get(algo, (160, 160, 160)), dtype=float)
    shade = 1.25 - 0.6 * min(max(k, 1), 20) / 20
    return tuple(int(v) for v in np.clip(base * shade, 0, 255))


def experiment_blueprint():
    import rerun.blueprint as rrb

    plot = rrb.TimeSeriesView
    return rrb.Blueprint(
        rrb.Grid(
            plot(origin="experiment/collisions", name="Collisions per episode (mean over seeds)"),
            plot(origin="experiment/cumulative_collisions", name="Cumulative collisions"),
            plot(origin="experiment/steps", name="Steps per episode"),
            plot(origin="experiment/extra_steps", name="Steps above the shortest path"),
            plot(origin="experiment/reward_sum", name="Reward sum"),
            plot(origin="experiment/arrived", name="Share of episodes arriving"),
            grid_columns=3,
        ),
        rrb.TimePanel(timeline="episode", state="collapsed"),
        collapse_panels=False,
    )
