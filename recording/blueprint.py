"""The viewer's first view of a run: the world and its key | the learning curves | the heat maps."""

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.loggers import heat_map_agents


REFERENCE_STEPS = "metrics/steps/paper_ql"
"""The paper's QL's steps ratio (``recording.reference``): 10 to 20 where the run's own is 1 to
4, it has a plot of its own beside the run's, which it would flatten."""


def blueprint(config: SwarmConfig, distributed: bool = True, map_agent: int | None = 0,
              reference: bool = False):
    """The first view: the world and its key | the learning curves | the heat maps.

    The viewer opens on the ``episode`` timeline, following the newest episode: the curves run
    against episodes, and the world view shows that whole episode at once (every announced move,
    every wait, every collision; agents, goals and trails as the episode left them).
    """
    import rerun.blueprint as rrb

    from nnql_swarm.recording import world as world_viz

    episode = rrb.VisibleTimeRanges(timeline="episode",
                                    start=rrb.TimeRangeBoundary.cursor_relative(seq=0),
                                    end=rrb.TimeRangeBoundary.cursor_relative(seq=0))
    world_view = rrb.Spatial2DView(
        origin="world", name="World: the episode's moves, waits and collisions",
        visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, config.width - 0.4],
                                         y_range=[-0.5 - world_viz.caption_room(config),
                                                  config.height - 0.4]),
        overrides={path: episode for path in episode_wide(config)},
    )
    events = rrb.TextLogView(origin=world_viz.EVENTS, name="Events", columns=rrb.TextLogColumns(
        timeline_columns=[rrb.encodings.TimelineColumn("episode"),
                          rrb.encodings.TimelineColumn("tick", visible=False)],
        text_log_columns=[rrb.components.TextLogColumn("LogLevel"),
                          rrb.components.TextLogColumn("Body")]))
    key = rrb.TextDocumentView(origin=world_viz.LEGEND, name="Key")
    whole_run = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                      end=rrb.TimeRangeBoundary.infinite()))

    def plot(span: tuple[float, float] | None = None, legend: bool = False,
             **view) -> rrb.TimeSeriesView:
        """A learning curve. No key over the curves where the title says what they are; the
        negotiation wait's, one curve per agent, in the top right corner."""
        axis = None if span is None else rrb.ScalarAxis(range=span)
        return rrb.TimeSeriesView(axis_x=whole_run, axis_y=axis,
                                  plot_legend=rrb.PlotLegend(corner="RightTop", visible=legend),
                                  **view)

    n = config.n_agents
    steps = ["metrics/steps/over_shortest", "metrics/steps/smoothed", "metrics/steps/shortest_path"]
    metrics = rrb.Grid(
        plot(origin="metrics/throughput", name="Throughput: goals a step") if config.lifelong
        else plot((0.0, 1.05), origin="metrics/arrived_share", name="Share of agents arrived"),
        plot(origin="metrics/steps", contents=steps,
             name="Steps / shortest, smoothed"),
        plot(origin="metrics/refused", name="First choices refused")
        if config.arbitration == "pibt"  # nobody collides: the conflicts are refusals
        else plot((0.0, float(max(2 * n, 8))), origin="metrics/collisions/per_episode",
                  name="Agents in a collision"),
        plot(origin="metrics/negotiation/awaited_per_tick", name="Intents awaited per tick"),
        plot(origin="metrics/negotiation/latency_ms", name="Negotiation wait (ms)", legend=True)
        if distributed else plot(origin="metrics/steps/episode", name="Ticks per episode"),
        plot(origin="metrics/steps", contents=[*steps, REFERENCE_STEPS],
             name="Steps ratio: paper's QL in grey") if reference
        else plot(origin="metrics/ticks_per_s", name="Ticks per second"),
        grid_columns=2, name="Learning curves (x: episode)",
    )
    from nnql_swarm.recording import known_map
    from nnql_swarm.recording.agent import DS_STATE_TITLES

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
    learned: rrb.Tabs | rrb.Vertical = heat_maps
    if map_agent is not None and 0 <= map_agent < n and known_map.shows_known_map(config):
        learned = rrb.Vertical(rrb.Spatial2DView(
            origin=known_map.ROOT, background=[255, 255, 255],
            name=f"Agent {map_agent}'s known map and planned path",
            visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, config.width - 0.4],
                                             y_range=[-0.6, config.height - 0.4])),
            heat_maps, row_shares=[2, 3])  # its newest path: all of an episode's are a comb
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


def episode_wide(config: SwarmConfig) -> list[str]:
    """The entities the world view shows for a whole episode on the ``episode`` timeline: every
    agent's path, announced moves and waits (``recording.agent_entities``), the collisions, and
    under priority inheritance and lifelong tasks the refusals, pushes and goals reached."""
    from nnql_swarm.recording import world as world_viz
    from nnql_swarm.recording.agent_entities import EPISODE_WIDE, part_paths

    return [*(path for part in EPISODE_WIDE for path in part_paths(config.n_agents, part)),
            world_viz.COLLISIONS, world_viz.REFUSED, world_viz.PUSHES, world_viz.REACHED]


def recorded_blueprint(config: SwarmConfig, chunks):
    """The blueprint of a saved run, from its recording's chunks: what the launcher told the
    world (a distributed run, ``--reference``, ``--map-agent``) read back from what it logged,
    so that a recording opened anywhere else (the notebook's ``show``) opens on the same view.

    Distributed: agents logged their negotiation wait over time; reference: the paper's QL's
    steps curve is there; map agent: the id in the known map's agent label (None: no map)."""
    from nnql_swarm.recording import known_map
    from nnql_swarm.recording.reference import CURVES

    distributed, reference, map_agent = False, False, None
    for chunk in chunks:
        entity = chunk.entity_path.lstrip("/")
        if entity.startswith("metrics/negotiation/latency_ms/") and not chunk.is_static:
            distributed = True
        elif entity in CURVES:
            reference = True
        elif entity == known_map.AGENT and chunk.is_static:
            labels = chunk.to_record_batch().column("Points2D:labels").to_pylist()
            map_agent = int(labels[0][0].split()[-1])
    return blueprint(config, distributed, map_agent, reference)
