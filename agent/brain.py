"""One swarm agent's decisions, pure: observation and neighbours' answers in, action out.

The agent process (``agent.agent_node``) runs it; it calls the learner's kernel functions
(``learning.learner``) on Python lists and its tables' array, the very functions the swarm
simulator (``sim.episode``) runs compiled, so that for the same seed the distributed swarm and the
simulator play the same run.

Negotiation: at every tick an agent that reads intents waits for the intents of its higher-ranked
neighbours within reach (``learning.planner.Plan.awaited``, by ``protocol.ranks.waits_for``; how it
learns them is that module's plan), and decides with those of them it needs
(:meth:`AgentBrain.neighbours_to_ask`), with whatever came back
(:meth:`AgentBrain.act`), and then answers for itself. A neighbour whose intent did not come is
read as one whose intent is unknown, from its current cell. A QL agent asks nobody.
"""

import numpy as np

from nnql_swarm.learning import ahead
from nnql_swarm.learning.decision import OUT_ACTION, OUT_FIELDS, OUT_ORDERED, OUT_WRITTEN
from nnql_swarm.learning.fields import (
    LP_READING, LP_SHIELD, LP_STILL_SHIELD, NB_FIELDS, READ_DAQL, READINGS, Grid, Sight,
)
from nnql_swarm.learning.learner import draw_noise, make_way
from nnql_swarm.learning.record import write_updates
from nnql_swarm.learning.rows import NeighbourRows
from nnql_swarm.learning.tables import Learner, buffer_makers
from nnql_swarm.protocol.actions import N_ACTIONS, STAY
from nnql_swarm.protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from nnql_swarm.protocol.jit import floats, python_values, rows
from nnql_swarm.protocol.messages import Observation, unpack_neighbours
from nnql_swarm.protocol.seeding import AGENT_STREAM, stream_rng


class AgentBrain:
    """An agent's learner, its noise, and what it remembers of its last observation.

    Where the swarm shares one table (``config.shared``), every agent holds a copy: its own
    learning record of a tick is not applied at once but goes out with its intent
    (:attr:`learned`); the world applies every agent's records of that tick to its own copy
    (``world.shared_table``) and hands everyone the entries they changed in the next
    observations, which each agent writes into its copy before it decides, so all copies stay
    equal (and equal to the simulator's one table).
    """

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        if config.algo not in READINGS:
            raise ValueError(f"--algo {config.algo} plans centrally; run it with --in-process")
        if config.lookahead > 1:
            raise ValueError("a lookahead n > 1 is played by the simulator only (--in-process)")
        self.agent = agent
        self.config = config
        self._decide, self.decides = ahead.KERNELS.compiled("agent_decision")
        """The decision's kernel (``learning.decision.agent_decision``) and how it runs here:
        compiled ahead of time, by numba, or in plain Python (``learning.ahead``)."""
        self._arrays = self.decides != ahead.PLAIN  # its buffers: arrays where it is compiled
        self.learner = Learner(config, self._arrays)
        self._write_entries, _ = ahead.KERNELS.compiled("write_entries")  # as the decision runs
        self.learned: tuple = ()  # this tick's learning record, for the intent (shared tables)
        self.order: tuple[int, ...] = ()  # this tick's moves by preference (--arbitration pibt)
        self._pibt = config.arbitration == "pibt"
        ints, _, _ = buffer_makers(self._arrays)
        self._ranks = ints([0] * N_ACTIONS)
        self._outcome = ints([0] * OUT_FIELDS)
        self.rejected_updates = 0  # shared-table entries refused (outside, or uneven groups)
        self.reads_intents = config.algo in NEGOTIATING_ALGOS
        self.rng = stream_rng(config.seed, AGENT_STREAM, agent)
        self._random_actions = np.zeros(config.max_steps, dtype=np.int64)
        self._ties = np.zeros((config.max_steps, N_ACTIONS))
        self._noise: tuple = (self._random_actions, self._ties)
        """The episode's noise as the kernel reads it: the arrays, or their values as lists."""
        self._noise_episode = -1
        self._prepared = (-1, -1)  # the observation prepared last (episode, tick)
        self._seen: tuple = (-1, {}, None)  # DAQL: last tick's cells, and the agent's own
        self._was_at: tuple[int, int] | None = None  # DAQL: the agent's cell a tick ago
        params = self.learner.params
        self._remembers = (params[LP_READING] == READ_DAQL or self._pibt
                           or bool(params[LP_SHIELD] and params[LP_STILL_SHIELD]))
        """Whether a decision reads the cells of the tick before (:meth:`_previous_cells`)."""
        self._rows = NeighbourRows(config)
        self._wall_x, self._wall_y = ints(self._rows.wall_x.tolist()), ints(self._rows.wall_y.tolist())
        self._grid = Grid(config.width, config.height, self._wall_x, self._wall_y, 0,
                          len(self._wall_x))

    def neighbours_to_ask(self, obs: Observation, awaited: list[int]) -> list[int]:
        """The neighbours whose intents this agent decides with, of those it waits for
        (``awaited``, ``learning.planner.Plan.awaited``): none at an episode's end, nor once it
        has parked on its goal (``SwarmConfig.step_aside`` off), where it stays (it still waits,
        to relay them down the chain); an arrived agent that may step aside needs them to make way."""
        if (obs.arrived and not self.config.step_aside) or obs.episode_end \
                or not self.reads_intents:
            return []
        return awaited

    def prepare(self, obs: Observation) -> None:
        """What a decision on ``obs`` needs before the intents: the shared records applied, the
        episode's noise drawn (an agent prepares while it waits for its neighbours' intents)."""
        if self._prepared == (obs.episode, obs.tick):
            return
        self._prepared = (obs.episode, obs.tick)
        if self.config.shared and obs.updates:
            self.rejected_updates += write_updates(self.learner.entries, obs.updates,
                                                   self._write_entries, self._arrays)
        if ((obs.arrived and not self.config.step_aside) or obs.episode_end
                or self._noise_episode == obs.episode):
            return
        draw_noise(self.rng, self._random_actions, self._ties)
        if not self._arrays:  # plain Python reads lists several times faster
            self._noise = (self._random_actions.tolist(), self._ties.tolist())
        self._noise_episode = obs.episode

    def act(self, obs: Observation, answers: dict[int, int], seen: tuple = (None, None)) -> int:
        """Learn from the last action's rewards and choose this tick's action
        (``learning.decision.agent_decision``): STAY at an episode's end or once arrived, unless
        it must make way (``learning.learner.make_way``, the ``step-aside`` on-target rule).
        ``seen``: the observation's neighbours and parked ids as the kernels read them, where the
        caller has them (``learning.planner.Plan``)."""
        learner, config, outcome, rows = self.learner, self.config, self._outcome, self._rows
        self.prepare(obs)
        (x, y), (gx, gy) = obs.position, obs.goal
        stops = (obs.arrived and not config.lifelong) or obs.episode_end
        previous = self._previous_cells(obs, seen[0])
        cells, parked, was_x, was_y = rows.load(obs, {} if stops else answers, previous,
                                                self._was_at, *seen)
        reads_noise = not stops or (self._pibt and not obs.episode_end)
        assert self._noise_episode >= 0 or not reads_noise, "prepare draws the episode's noise"
        step = obs.step if reads_noise else 0
        random_actions, ties = self._noise
        self._decide(learner.q_ds, learner.q_ca, learner.params, learner.params_f,
                     learner.state, learner.state_f, learner.wmap, learner.rec, learner.rec_f,
                     learner.values, config.width, config.height, self._wall_x, self._wall_y,
                     x, y, gx, gy, cells, len(cells), rows.reach, rows.keep, parked, len(parked),
                     rows.answer, rows.prev_x, rows.prev_y, was_x, was_y,
                     not stops and rows.reads_intents, rows.wall_cells, rows.n_walls,
                     rows.wall_far, config.interaction_radius, config.meet_only, rows.out,
                     obs.step == 0, obs.reward_ds, obs.reward_ca, obs.arrived, stops,
                     obs.episode_end, self._pibt, not config.shared, random_actions[step],
                     ties[step], self._ranks, outcome)
        action = outcome[OUT_ACTION]
        self.order = self._ordered() if outcome[OUT_ORDERED] else ()
        if stops and not obs.episode_end and not self._pibt and config.step_aside:
            action = self._make_way(obs, answers)
        self.learned = (learner.record(),) if config.shared and outcome[OUT_WRITTEN] else ()
        return int(action)

    def _ordered(self) -> tuple[int, ...]:
        """The moves in the order of this tick's ranks (``learning.learner.preference_ranks``)."""
        return tuple(sorted(range(N_ACTIONS), key=self._ranks.__getitem__))

    def _make_way(self, obs: Observation, answers: dict[int, int]) -> int:
        """An arrived agent's move under ``step-aside``: it stays unless a neighbour it waited
        for announced moving into its cell."""
        noise = self._noise
        assert self._noise_episode >= 0, "prepare draws the episode's noise before a decision"
        near = self._neighbour_rows(obs, answers, True)
        (x, y), (gx, gy) = obs.position, obs.goal
        sight = Sight(x, y, gx, gy, rows(near, NB_FIELDS), len(near), False)
        return make_way(sight, self.config.n_agents, self._grid, floats(noise[1][obs.step]))

    def _neighbour_rows(self, obs: Observation, answers: dict[int, int], announcing: bool,
                        seen: tuple = (None, None)):
        """The learner's neighbour rows for this observation (:class:`NeighbourRows`), with
        DAQL's memory of the tick before."""
        previous = self._previous_cells(obs, seen[0])
        return self._rows(obs, answers, announcing, previous, self._was_at, *seen)

    def _previous_cells(self, obs: Observation, cells=None) -> dict[int, tuple[int, int]]:
        """DAQL's (the still shield's, and the hindrance's under ``--arbitration pibt``) memory:
        the neighbours' cells at the previous tick of this episode, where they were in view, and
        the agent's own then (:attr:`_was_at`); and this tick's, for the next (``cells``: the
        observation's neighbours as the plan read them, where the caller has them)."""
        if not self._remembers:
            return {}
        tick, before, was_at = self._seen
        recent = tick == obs.tick - 1 and obs.step > 0
        self._was_at = was_at if recent else None
        rows = python_values(unpack_neighbours(obs.neighbours) if cells is None else cells)
        self._seen = (obs.tick, {j: (jx, jy) for j, jx, jy in rows}, obs.position)
        return before if recent else {}
