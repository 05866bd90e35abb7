#!/usr/bin/env python3
"""What each part of an agent's handling of its inputs costs, hot in one thread.

Runs the real handlers of a whole run in one process (``bench.node_cpu``'s harness: the world
and every agent, each message delivered in order) with the parts of an agent's work timed by
the thread's CPU clock: its machine's handling of an observation and of an answer as wholes, and
inside them the decision (``AgentBrain.act``, with ``prepare``: the shared table's updates
written, the episode's noise drawn), the codec's decoding of each message, the negotiation's
plan (``agent.negotiation.Planner``: whom to wait for and ask, whom to answer, the parked
neighbours known to stay, the agents near enough to stream), the answers through the standing
queries it holds and their review (``AgentMachine._answer_standing_queries``) and the encoding
of answers and intents; and, inside the plan and the decision, their two kernels compiled ahead of
time alone (:data:`KERNEL_PARTS`), so that what is left of those parts is the Python around them.
Each part's CPU time summed over the run, by observation, so the parts of one observation add up
(a part also called on answers, as decoding, counts there too). Each timer costs about half a
microsecond a call. Where the next microseconds are:

    python -m bench.agent_parts --agents 8 --episodes 10
    python -m bench.agent_parts --agents 64 --episodes 4
"""

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("NNQL_KERNEL", "python")  # as in the swarm's processes, unless told

from bench import node_cpu  # noqa: E402
from bench.harness import add_preset_option, grid_side, swarm_config  # noqa: E402
from nnql_swarm.agent import agent_machine, brain, negotiation  # noqa: E402
from nnql_swarm.learning import ahead  # noqa: E402
from nnql_swarm.protocol import inbox  # noqa: E402

PARTS = (
    ("the observation, in all", agent_machine.AgentMachine, "on_observation"),
    ("an answer, in all", agent_machine.AgentMachine, "on_answer"),
    ("the decision (act)", brain.AgentBrain, "act"),
    ("prepare (updates, noise)", brain.AgentBrain, "prepare"),
    ("decoding messages", inbox.Inbox, "decode"),
    ("the negotiation's plan", negotiation.Planner, "__call__"),
    ("standing queries answered", agent_machine.AgentMachine, "_answer_standing_queries"),
    ("encoding", agent_machine, "encode"),
)
"""``(name, owner, attribute)``: each part, timed where the agent's machine calls it."""

KERNEL_PARTS = (
    ("the plan's kernel", "agent_plan"),
    ("the decision's kernel", "agent_decision"),
)
"""``(name, kernel)``: the kernels of the plan and the decision (which reads the neighbour rows
too), each timed as the process runs it (``learning.ahead``)."""

def timed(spent: list[int], function):
    def part(*args, **kwargs):
        start = time.thread_time_ns()
        try:
            return function(*args, **kwargs)
        finally:
            spent.append(time.thread_time_ns() - start)
    return part


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--agents", type=int, default=8)
    p.add_argument("--episodes", type=int, default=10)
    p.add_argument("--max-steps", type=int, default=100)
    p.add_argument("--repeats", type=int, default=2)
    add_preset_option(p)
    args = p.parse_args(argv)
    side = grid_side(args.agents)
    config = swarm_config(args.preset, run_id="parts", n_agents=args.agents,
                          episodes=args.episodes, max_steps=args.max_steps, width=side,
                          height=side)
    spent: dict[str, list[int]] = {name: [] for name, _, _ in PARTS}
    # The machine reads its collaborators through their modules, so each is timed in place.
    for name, owner, attribute in PARTS:
        setattr(owner, attribute, timed(spent[name], getattr(owner, attribute)))
    spent.update((name, []) for name, _ in KERNEL_PARTS)
    kernel_part = {kernel: name for name, kernel in KERNEL_PARTS}
    compiled = ahead.KERNELS.compiled

    def timed_kernel(kernel: str):  # each kernel is looked up once, as its holder is made
        function, how = compiled(kernel)
        part = kernel_part.get(kernel)
        return (function, how) if part is None else (timed(spent[part], function), how)

    ahead.KERNELS.compiled = timed_kernel  # type: ignore[method-assign]
    deciding = ahead.KERNELS.compiled("agent_decision")[1]
    print(f"{args.agents} agents, {args.preset}, deciding {deciding}; "
          "us of CPU an observation, each repeat (calls):")
    rows = {name: [] for name in spent}
    for _ in range(args.repeats):
        for times in spent.values():
            times.clear()
        with tempfile.TemporaryDirectory() as out:
            node_cpu.run(config, Path(out), False)
        observations = len(spent["the observation, in all"])
        for name, times in spent.items():
            rows[name].append(f"{sum(times) / observations / 1000:.1f} ({len(times)})")
    for name, figures in rows.items():
        print(f"  {name:28s} " + "  ".join(f"{f:>16s}" for f in figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
