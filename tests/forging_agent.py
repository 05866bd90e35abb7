"""A compromised agent process: authenticated as itself, it plays honestly, but from a given tick
on its learning records are forged (``sim.forgery``: collisions pay), or, with ``--mute``, it
sends none. ``tests/test_forgery.py`` starts it beside a swarm's world and honest agents.

    python tests/forging_agent.py --from-tick T [--mute] <launch/swarm.py options for
        --role agents --agent-ids I>
"""

import os
import sys

os.environ.setdefault("NNQL_KERNEL", "python")  # as the launcher runs its agents; before imports

from nnql_swarm.agent.brain import AgentBrain  # noqa: E402
from nnql_swarm.agent.agent_node import AgentOptions, run_agent  # noqa: E402
from nnql_swarm.launch import swarm_cli  # noqa: E402
from nnql_swarm.sim.forgery import forged  # noqa: E402


class ForgingBrain(AgentBrain):
    """An agent's brain whose records lie from tick ``from_tick`` on (or are left out)."""

    def __init__(self, agent, config, from_tick: int, mute: bool) -> None:
        super().__init__(agent, config)
        self.from_tick, self.mute = from_tick, mute

    def act(self, obs, answers, seen=(None, None)):
        action = super().act(obs, answers, seen)
        if self.learned and obs.tick >= self.from_tick:
            self.learned = () if self.mute else (forged(self.learned[0]),)
        return action


def main(argv: list[str]) -> int:
    from_tick = int(argv[argv.index("--from-tick") + 1])
    mute = "--mute" in argv
    rest = [a for k, a in enumerate(argv)
            if a not in ("--from-tick", "--mute") and (k == 0 or argv[k - 1] != "--from-tick")]
    args = swarm_cli.build_parser().parse_args(rest)
    config, launch, out = swarm_cli.resolve(args)
    swarm_cli.prepare_out_dir(out, config, "agents")
    _, transport, _ = swarm_cli.transports(launch, config)
    [agent] = launch.agent_ids
    brain = ForgingBrain(agent, config, from_tick, mute)
    return run_agent(AgentOptions(agent, config, transport(agent), out), brain)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
