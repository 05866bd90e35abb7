"""What a handler compiled whole would still do, taken from a recorded run: the codec and the
kernels of an agent's decision and of the world's check of a record, on the arguments the run's
own handlers passed them (:class:`KernelWork`, caught by :func:`capturing` while
``bench.node_cpu``'s harness runs them). ``bench.pattern --kernels`` replays the swarm's messages
with this work in each handler."""

import contextlib
import inspect
from collections import defaultdict
from dataclasses import dataclass, field


AGENT_KERNELS = ("agent_plan", "agent_decision")
"""The kernels of an agent's decision, in the order it calls them (``learning.ahead``)."""
CHECK_KERNEL = "expected_record"
"""The kernel of the world's check of a learning record."""
CHECKS_KEPT = 16
"""How many of the run's last record checks the world's work cycles through."""


def _stops_argument(kernel: str) -> int:
    """Where the kernel ``kernel`` takes ``stops`` (the agent arrived, or the episode ended: it
    decides nothing, and its work is the smaller)."""
    from nnql_swarm.learning import ahead

    function = ahead.KERNELS.exports[kernel][0]
    return list(inspect.signature(getattr(function, "py_func", function)).parameters).index("stops")


@dataclass
class KernelWork:
    """What a compiled handler would still do, from a recorded run: per agent, its last
    observation's and intent's payloads and the arguments of the last calls of
    :data:`AGENT_KERNELS` by which it decided (not stopped); for the world, intents' payloads and
    the arguments of the run's last :data:`CHECKS_KEPT` calls of :data:`CHECK_KERNEL` for such
    decisions."""

    run_id: str
    observations: dict[int, bytes] = field(default_factory=dict)
    intents: dict[int, bytes] = field(default_factory=dict)
    calls: dict[int, dict[str, tuple]] = field(default_factory=lambda: defaultdict(dict))
    checks: list[tuple] = field(default_factory=list)

    def part(self, agent: int | None) -> "KernelWork":
        """What one process needs of it: ``agent``'s, or the world's (None)."""
        if agent is None:
            return KernelWork(self.run_id, intents=self.intents, checks=self.checks)
        mine = KernelWork(self.run_id)
        for held, kept in ((self.observations, mine.observations), (self.intents, mine.intents),
                           (self.calls, mine.calls)):
            if agent in held:
                kept[agent] = held[agent]
        return mine

    def agent_work(self, agent: int):
        """The work of ``agent``'s decision, to run in its process (the kernels loaded there),
        or None where the run gave it no decision to copy."""
        from nnql_swarm.learning import ahead
        from nnql_swarm.protocol.messages import Intent, Observation, encode, parse

        calls = self.calls.get(agent, {})
        if agent not in self.observations or agent not in self.intents or \
                any(name not in calls for name in AGENT_KERNELS):
            return None
        run_id, payload = self.run_id, self.observations[agent]
        intent = parse(self.intents[agent], Intent, run_id)
        kernels = [(ahead.KERNELS.compiled(name)[0], calls[name]) for name in AGENT_KERNELS]

        def work() -> None:
            parse(payload, Observation, run_id)
            for kernel, args in kernels:
                kernel(*args)
            encode(intent)
        return work

    def world_work(self):
        """The work of each intent the world counts, to run in its process."""
        from itertools import cycle

        from nnql_swarm.learning import ahead
        from nnql_swarm.protocol.messages import Intent, parse

        if not self.checks or not self.intents:
            return None
        check, run_id = ahead.KERNELS.compiled(CHECK_KERNEL)[0], self.run_id
        turns = cycle(zip(cycle(self.intents.values()), self.checks))

        def work() -> None:
            payload, args = next(turns)
            parse(payload, Intent, run_id)
            check(*args)
        return work


@contextlib.contextmanager
def capturing(work: KernelWork):
    """Keep the arguments of every agent's last calls of :data:`AGENT_KERNELS` by which it
    decided, and of the world's last :data:`CHECKS_KEPT` calls of :data:`CHECK_KERNEL` for such
    decisions, into ``work``, while the handlers made meanwhile run."""
    from nnql_swarm.agent import agent_machine, brain
    from nnql_swarm.world import records

    deciding, checking = _stops_argument(AGENT_KERNELS[-1]), _stops_argument(CHECK_KERNEL)
    pending: dict[int, dict[str, tuple]] = defaultdict(dict)  # agent -> its calls not decided on

    def keep(agent: int, name: str, kernel):
        def call(*args):
            pending[agent][name] = args
            if name == AGENT_KERNELS[-1] and not args[deciding]:
                work.calls[agent].update(pending.pop(agent))
            return kernel(*args)
        return call

    def check(kernel):
        def call(*args):
            if not args[checking]:
                work.checks.append(args)
                del work.checks[:-CHECKS_KEPT]
            return kernel(*args)
        return call

    def machine_init(self, agent, *args, **kwargs):
        inits[0](self, agent, *args, **kwargs)
        self.planner._plan = keep(agent, AGENT_KERNELS[0], self.planner._plan)

    def brain_init(self, agent, *args, **kwargs):
        inits[1](self, agent, *args, **kwargs)
        self._decide = keep(agent, AGENT_KERNELS[1], self._decide)

    def check_init(self, *args, **kwargs):
        inits[2](self, *args, **kwargs)
        self._expected = check(self._expected)

    owners = (agent_machine.AgentMachine, brain.AgentBrain, records.RecordCheck)
    inits = [owner.__init__ for owner in owners]
    for owner, init in zip(owners, (machine_init, brain_init, check_init)):
        owner.__init__ = init  # type: ignore[method-assign]
    try:
        yield
    finally:
        for owner, init in zip(owners, inits):
            owner.__init__ = init  # type: ignore[method-assign]
