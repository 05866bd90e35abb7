"""Which process logs what: the world's logger, the recorded agents' loggers, the in-process
runner's, each opened on its process's sinks (``recording.sinks``)."""

from pathlib import Path

from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.recording.shown import learns
from nnql_swarm.recording.sinks import RecordingPlan, plan_of

RECORDED_AGENTS = 8
"""Agents ``0 .. RECORDED_AGENTS - 1`` log their own entities (heat maps, negotiation timing);
the others log nothing and never load Rerun. The world's entities show every agent, each entity
all of them at once: a viewer slows down with hundreds of entities, and 128 agents logging their
own would give it over a thousand."""


def logs_own_heat_maps(agent: int, config: SwarmConfig) -> bool:
    """Whether a recorded agent logs its heat maps: each of them, or only agent 0 where the
    agents share one table (the same table in every copy); nobody where the agents learn no
    tables (``recording.shown``)."""
    return agent < RECORDED_AGENTS and (agent == 0 or not config.shared) and learns(config)


def heat_map_agents(config: SwarmConfig) -> list[int]:
    """The agents whose heat maps the recording holds."""
    return [i for i in range(min(config.n_agents, RECORDED_AGENTS))
            if logs_own_heat_maps(i, config)]


def open_world_viz(record, config: SwarmConfig, out: Path, distributed: bool = True):
    """The world's logger (``recording.world.WorldViz``) with the blueprint, or None if not recording.
    ``distributed``: the agents are processes that time their negotiation (the blueprint plots
    it)."""
    plan = plan_of(record, config, out)
    if plan is None:  # a world that does not record never loads Rerun
        return None
    from nnql_swarm.recording.blueprint import blueprint
    from nnql_swarm.recording.world import WorldViz
    from nnql_swarm.world.metrics import read_episodes

    episodes = Path(out) / "episodes.csv"  # a resumed run's complete episodes so far
    before = sum(int(row["collisions"]) for row in read_episodes(episodes)) \
        if episodes.exists() else 0
    viz = WorldViz(config, plan.open("world", blueprint(config, distributed, plan.map_agent,
                                                      plan.reference)),
                   collisions_before=before, map_agent=plan.map_agent, files=plan.parts_dir)
    if plan.url is not None:
        viz.row_flush_s = 0.0
    return viz


def open_agent_viz(plan: RecordingPlan | None, agent: int, config: SwarmConfig):
    """``(brain, on_episode_end, viz)`` for an agent process; all None if not recording."""
    if plan is None or not plan.enabled:
        return None, None, None
    if agent >= RECORDED_AGENTS:
        return None, None, None
    from nnql_swarm.recording.agent import AgentViz, TimedBrain

    viz = AgentViz(agent, config, plan.open(f"agent-{agent}"),
                   heat_maps=logs_own_heat_maps(agent, config))
    return TimedBrain(agent, config), viz.on_episode_end, viz


class InProcessRecorder:
    """World and agents of the in-process runner logging into one stream."""

    def __init__(self, record, config: SwarmConfig, out: Path) -> None:
        from nnql_swarm.recording.agent import AgentViz

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
