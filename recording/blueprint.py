"""The viewer's first view of a run: the world and its key | the learning curves | the heat maps."""

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.loggers import heat_map_agents
from nnql_swarm.recording.shown import ca_learns, learns, negotiates


REFERENCE_STEPS = "metrics/steps/paper_ql"
"""The paper's QL's steps ratio (``recording.reference``): 10 to 20 where the run's own is 1 to
4, it has a plot of its own beside the run's, which it would flatten."""


def blueprint(config: SwarmConfig, distributed: bool = True, map_agent: int | None = 0,
              reference: bool = False, follow: int | None = None):
    """The first view: the world and its key | the learning curves | the heat maps.

    The viewer opens on the ``episode`` timeline, following the newest episode: the curves run
    against episodes, and the world view shows that whole episode at once (every announced move,
    every wait, every collision; agents, goals and trails as the episode left them).

    ``follow``: an agent followed instead, on the ``tick`` timeline (the time panel open): the
    world view shows every agent's disc but only that agent's (or its group's) trail, path,
    moves, waits, goal and start (``recording.follow``).
    """
    import rerun.blueprint as rrb

    from nnql_swarm.recording import world as world_viz

    episode = rrb.VisibleTimeRanges(timeline="episode",
                                    start=rrb.TimeRangeBoundary.cursor_relative(seq=0),
                                    end=rrb.TimeRangeBoundary.cursor_relative(seq=0))
    from nnql_swarm.recording.agent_entities import crowded

    name = ("World: the episode's paths, jams and collisions" if crowded(config.n_agents)
            else "World: the episode's moves, waits and collisions")
    contents = ["$origin/**"]
    if follow is not None:
        from nnql_swarm.recording.agent_entities import DISC, owner_index, owners

        held = owners(config.n_agents)
        own = held[int(owner_index(config.n_agents)[follow])][0]
        name = f"World: agent {follow} followed, tick by tick"
        contents = ["+ world/**", "- world/agents/**", f"+ {own}/**",
                    *(f"+ {path}/{DISC}" for path, _ in held)]
    world_view = rrb.Spatial2DView(
        origin="world", name=name, contents=contents,
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
    n = config.n_agents
    metrics = learning_curves(config, distributed, reference)
    from nnql_swarm.recording import known_map_view
    from nnql_swarm.recording.agent import DS_STATE_TITLES

    shared = config.shared

    def q_ds(i: int, whose: str):
        if config.ds_state == "goal":
            return rrb.Spatial2DView(origin=f"agents/{i}/q_ds", background=[255, 255, 255],
                                     name=f"{whose} Q_DS: goal offset")
        return rrb.TextDocumentView(origin=f"agents/{i}/q_ds/table",
                                    name=f"{whose} Q_DS {DS_STATE_TITLES[config.ds_state]}")

    def q_ca(i: int):
        return rrb.Spatial2DView(origin=f"agents/{i}/q_ca", background=[255, 255, 255],
                                 name="Shared Q_CA: neighbour offset" if shared
                                 else f"Agent {i} Q_CA: neighbour offset")

    heat_maps = rrb.Tabs(*[
        rrb.Vertical(
            *([q_ds(i, "Shared" if shared else f"Agent {i}"), q_ca(i)] if ca_learns(config)
              else [q_ds(i, "Shared" if shared else f"Agent {i}")]),
            name="shared table" if shared else f"agent {i}",
        )
        for i in heat_map_agents(config)
    ], active_tab=0, name="What the agents learned") if heat_map_agents(config) else None
    learned: rrb.Tabs | rrb.Vertical | rrb.Spatial2DView | None = heat_maps
    if map_agent is not None and 0 <= map_agent < n and known_map_view.shows_known_map(config):
        map_view = rrb.Spatial2DView(
            origin=known_map_view.ROOT, background=[255, 255, 255],
            name=f"Agent {map_agent}'s known map and planned path",
            visual_bounds=rrb.VisualBounds2D(x_range=[-0.6, config.width - 0.4],
                                             y_range=[-0.6, config.height - 0.4]))
        learned = map_view if heat_maps is None else rrb.Vertical(
            map_view, heat_maps, row_shares=[2, 3] if ca_learns(config) else [3, 2])
    columns: list = [rrb.Vertical(world_view, events, row_shares=[3, 1] if n < 64 else [4, 1]),
               rrb.Vertical(metrics, key, row_shares=[3, 2])]
    if learned is not None:
        columns.append(learned)
    return rrb.Blueprint(
        rrb.Horizontal(*columns, column_shares=[5, 5, 3][:len(columns)]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        rrb.TimePanel(timeline="episode", play_state="following", state="collapsed")
        if follow is None else rrb.TimePanel(timeline="tick", play_state="following",
                                             state="expanded"),
        collapse_panels=False,
    )


def learning_curves(config: SwarmConfig, distributed: bool = True, reference: bool = False):
    """The learning curves against episodes, each plot a curve that has something to show
    under the run's preset (``recording.shown``); with ``reference``, the paper's QL's steps."""
    import rerun.blueprint as rrb

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
    curves = [
        plot(origin="metrics/throughput", name="Throughput: goals a step") if config.lifelong
        else plot((0.0, 1.05), origin="metrics/arrived_share", name="Share of agents arrived"),
        plot(origin="metrics/steps", contents=steps, name="Steps / shortest, smoothed"),
        plot(origin="metrics/refused", name="First choices refused")
        if config.arbitration == "pibt"  # nobody collides: the conflicts are refusals
        else plot((0.0, float(max(2 * n, 8))), origin="metrics/collisions/per_episode",
                  name="Agents in a collision"),
        plot(origin="metrics", contents=["metrics/reward_sum", "metrics/reward_smoothed"],
             name="Reward, smoothed"),
    ]
    if negotiates(config):  # nobody else waits for anyone
        curves.append(plot(origin="metrics/negotiation/awaited_per_tick",
                           name="Intents awaited per tick"))
    curves.append(plot(origin="metrics/negotiation/latency_ms", name="Negotiation wait (ms)",
                       legend=True) if distributed and negotiates(config)
                  else plot(origin="metrics/steps/episode", name="Ticks per episode"))
    if learns(config):
        curves.append(plot((0.0, 1.05), origin="metrics/explored", legend=True,
                           name="States met (exploration)"))
    if reference:
        curves.append(plot(origin="metrics/steps", contents=[*steps, REFERENCE_STEPS],
                           name="Steps ratio: paper's QL in grey"))
    return rrb.Grid(*curves, grid_columns=2, name="Learning curves (x: episode)")


def episode_wide(config: SwarmConfig) -> list[str]:
    """The entities the world view shows for a whole episode on the ``episode`` timeline: every
    agent's path, announced moves and waits (from ``CROWDED_FROM`` agents on, the path alone:
    ``recording.agent_entities.episode_parts``), the collisions, and under priority inheritance
    and lifelong tasks the refusals, pushes and goals reached."""
    from nnql_swarm.recording import world as world_viz
    from nnql_swarm.recording.agent_entities import episode_parts, part_paths

    parts = episode_parts(config.n_agents)
    return [*(path for part in parts for path in part_paths(config.n_agents, part)),
            world_viz.COLLISIONS, world_viz.REFUSED, world_viz.PUSHES, world_viz.REACHED]


def recorded_blueprint(config: SwarmConfig, chunks):
    """The blueprint of a saved run, from its recording's chunks: what the launcher told the
    world (a distributed run, ``--reference``, ``--map-agent``) read back from what it logged,
    so that a recording opened anywhere else (the notebook's ``show``) opens on the same view."""
    distributed, reference, map_agent = recorded_options(chunks)
    return blueprint(config, distributed, map_agent, reference)


def recorded_options(chunks) -> tuple[bool, bool, int | None]:
    """``(distributed, reference, map_agent)`` of a recorded run, from its chunks.

    Distributed: agents logged their negotiation wait over time; reference: the paper's QL's
    steps curve is there; map agent: the id in the known map's agent label (None: no map)."""
    from nnql_swarm.recording import known_map_view
    from nnql_swarm.recording.reference import CURVES

    distributed, reference, map_agent = False, False, None
    for chunk in chunks:
        entity = chunk.entity_path.lstrip("/")
        if entity.startswith("metrics/negotiation/latency_ms/") and not chunk.is_static:
            distributed = True
        elif entity in CURVES:
            reference = True
        elif entity == known_map_view.AGENT and chunk.is_static:
            labels = chunk.to_record_batch().column("Points2D:labels").to_pylist()
            map_agent = int(labels[0][0].split()[-1])
    return distributed, reference, map_agent
