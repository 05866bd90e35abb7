"""What the swarm benchmarks share: run a swarm (distributed or in-process) and time its ticks."""

import math
import sys
from pathlib import Path
from typing import Callable

from nnql_swarm.recording.sinks import RecordingPlan
from nnql_swarm.protocol.config import DEFAULT_PRESET, PRESETS, SwarmConfig
from nnql_swarm.transport.ports import wait_listening
from nnql_swarm.transport.settings import TransportSettings
from nnql_swarm.transport.topology import EmbeddedLayout, embedded_topology


SCALE_GRIDS = {8: 11, 16: 16, 32: 22, 64: 32, 128: 45}
"""The side of the square grid for a swarm of each size: about 16 cells per agent, as 8 agents on
the paper's 11 x 11 (the sizes of ``bench/scale.py``; others by the same density)."""


def grid_side(n: int) -> int:
    return SCALE_GRIDS.get(n, max(2, round(11 * math.sqrt(n / 8))))


def measured_ticks(out: Path) -> tuple[int, float, float]:
    """The ticks a swarm's rate counts: every episode's but the first's (which includes
    start-up). How many, and when they ran: their first's and last's seconds after the run's
    first tick opened (episodes follow one another without a gap)."""
    # not at the top: the agents fork from a server that imported this module
    from nnql_swarm.world.metrics import read_episodes

    first, *rows = read_episodes(out / "episodes.csv")
    began = float(first["duration_s"])
    return (sum(int(r["steps"]) + 1 for r in rows), began,
            began + sum(float(r["duration_s"]) for r in rows))


def measured_rate(out: Path) -> float:
    """Ticks per second over the ticks :func:`measured_ticks` counts."""
    ticks, began, ended = measured_ticks(out)
    return ticks / (ended - began)


def run_distributed(config: SwarmConfig, out: Path, record: bool,
                    agent_target: Callable | None = None, memory=None,
                    layout: EmbeddedLayout | None = None) -> float:
    """The launcher's world and agent processes on one machine; ``agent_target`` replaces the
    agents' entry point (same arguments as ``launch.processes.agent_main``); ``memory`` (a
    ``bench.procstat.MemorySampler``) is told every process as ``world`` and ``agent-<i>``;
    ``layout``: the launcher's for this many agents unless given (a mesh up to
    ``transport.topology.HUB_FROM_AGENTS``, then the world as hub)."""
    from nnql_swarm.launch.processes import agent_main, process_context, world_main

    ctx = process_context()  # the kernel uncompiled, as the launcher's world and agents run
    layout = layout or EmbeddedLayout(topology=embedded_topology(config.n_agents))
    out.mkdir(parents=True)
    plan = RecordingPlan.to_files(config, out) if record else False
    world = ctx.Process(target=world_main, args=(config, layout.world(), out, plan, False))
    agents = [ctx.Process(target=agent_target or agent_main,
                          args=(i, config, layout.agent(), out, False, plan or None))
              for i in range(config.n_agents)]
    world.start()
    if layout.agents_wait_for_hub and not wait_listening(layout.host, layout.port, 60.0):
        raise RuntimeError(f"the world does not listen on {layout.endpoint}")
    for agent in agents:
        agent.start()
    if memory is not None:
        memory.watch("world", world.pid)
        for i, agent in enumerate(agents):
            memory.watch(f"agent-{i}", agent.pid)
    world.join()
    for agent in agents:
        agent.join(10)
        if agent.is_alive():
            agent.kill()
    if world.exitcode != 0:
        raise RuntimeError(f"world exited with {world.exitcode}")
    return measured_rate(out)


def stay_agent_main(agent: int, config: SwarmConfig, transport: TransportSettings, out: Path,
                    resume: bool = False, recording=None) -> None:
    """An agent process (``launch.processes.agent_main``'s arguments) that negotiates exactly as
    the learning agent does but learns nothing and always stays: the swarm's messages and
    protocol with the learning taken out. (Imported here: in the agent process, which runs the
    kernel uncompiled.)"""
    from nnql_swarm.agent.brain import AgentBrain
    from nnql_swarm.agent.agent_node import AgentOptions, run_agent
    from nnql_swarm.protocol.actions import STAY

    class StayBrain(AgentBrain):
        def act(self, obs, answers, seen=(None, None)) -> int:
            return STAY

    sys.exit(run_agent(AgentOptions(agent, config, transport, out), StayBrain(agent, config)))


def run_local(config: SwarmConfig, out: Path, record: bool) -> float:
    """The same logic in one process (``--in-process``)."""
    from nnql_swarm.launch.swarm_cli import run_in_process

    out.mkdir(parents=True)
    run_in_process(config, out, record, progress=False)
    return measured_rate(out)


def add_preset_option(parser) -> None:
    """``--preset``: the learning options a benchmark's swarm runs with."""
    parser.add_argument("--preset", choices=tuple(PRESETS), default=DEFAULT_PRESET,
                        help=f"learning options (default {DEFAULT_PRESET}; nnql: the paper's, "
                             "everyone waiting for everyone in view)")


def agent_sizes(parser, text: str) -> list[int]:
    """``--agents``' comma-separated agent counts (each at least 2), or the parser's one-line
    error."""
    try:
        sizes = [int(v) for v in text.split(",")]
    except ValueError:
        parser.error(f"--agents takes comma-separated numbers, not {text!r}")
    if any(n < 2 for n in sizes):
        parser.error("need at least 2 agents per size")
    return sizes


def swarm_config(preset: str, **fields) -> SwarmConfig:
    """A benchmark's swarm config: the preset's learning options and the given fields. One the
    swarm cannot run (too many agents for the grid, a radius out of range: the benchmark's flags)
    stops the benchmark with the config's reason, in one line (exit status 2, as a bad flag)."""
    try:
        return SwarmConfig(**{**PRESETS[preset], **fields})
    except ValueError as error:
        print(f"{Path(sys.argv[0]).name}: error: {error}", file=sys.stderr)
        raise SystemExit(2) from None
