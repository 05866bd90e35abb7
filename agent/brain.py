"""One swarm agent's decisions, pure: observation and neighbours' answers in, action out.

The same object runs inside an agent process (``agent.node``) and in the in-process swarm
(``launch.inprocess``), which is what makes the two runs identical for the same seed.

Negotiation (DESIGN §2, the paper's hierarchical way): at every tick each agent has a rank
(``protocol.config.priority_rank``, rotating so nobody always yields). An nnQL agent asks its
visible higher-ranked neighbours for their intents (:meth:`AgentBrain.neighbours_to_ask`), decides
with whatever answers came back (:meth:`AgentBrain.act`), and then answers for itself. A neighbour
that did not answer is read the QL way, from its current cell. A QL agent asks nobody.
"""

import numpy as np

from agent.learning import EpisodeNoise, Hyper, Learners, View
from protocol.actions import STAY, intended_cell
from protocol.config import NEGOTIATING_ALGOS, SwarmConfig, priority_rank
from protocol.messages import Observation
from protocol.seeding import AGENT_STREAM, stream_rng


class AgentBrain:
    """A learner of batch one, its noise, and the episode bookkeeping around it."""

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        self.agent = agent
        self.config = config
        self.learner = Learners(
            random_step=np.array([config.random_step]),
            use_intents=np.array([config.algo in NEGOTIATING_ALGOS]),
            n_neighbours=config.n_agents,
            hyper=Hyper(config.alpha, config.gamma, config.beta),
            with_direction=np.array([config.algo == "nnql-dir"]),
        )
        self.rng = stream_rng(config.seed, AGENT_STREAM, agent)
        self._noise: EpisodeNoise | None = None
        self._noise_episode = -1

    def neighbours_to_ask(self, obs: Observation) -> list[int]:
        """The visible higher-ranked neighbours whose intents this agent waits for."""
        if self.config.algo not in NEGOTIATING_ALGOS or obs.arrived or obs.episode_end:
            return []
        n = self.config.n_agents
        return [j for j, _, _ in obs.neighbours if priority_rank(j, obs.tick, n) < obs.rank]

    def act(self, obs: Observation, answers: dict[int, int]) -> int:
        """Learn from the last action's rewards and choose this tick's action (STAY if done)."""
        self.learner.record(
            np.array([obs.reward_ds]), np.array([obs.reward_ca]), np.array([obs.arrived])
        )
        view = self._view(obs, answers)
        if obs.arrived or obs.episode_end:
            self.learner.finish(np.array([True]), view)
            return STAY
        if self._noise_episode != obs.episode:
            self._noise = EpisodeNoise.draw(self.rng, self.config.max_steps)
            self._noise_episode = obs.episode
        action = self.learner.decide(
            view,
            np.array([True]),
            self._noise.random_actions[obs.step: obs.step + 1],
            self._noise.tie_breakers[obs.step: obs.step + 1],
        )
        return int(action[0])

    def _view(self, obs: Observation, answers: dict[int, int]) -> View:
        c = self.config
        nb_cells = np.zeros((1, c.n_agents, 2), dtype=np.int64)
        nb_next = np.zeros((1, c.n_agents, 2), dtype=np.int64)
        nb_known = np.zeros((1, c.n_agents), dtype=bool)
        nb_visible = np.zeros((1, c.n_agents), dtype=bool)
        for j, x, y in obs.neighbours:
            nb_cells[0, j] = (x, y)
            nb_visible[0, j] = True
            if j in answers:
                nb_known[0, j] = True
                nb_next[0, j] = intended_cell(np.array([x, y]), answers[j], c.width, c.height)
        return View(
            own=np.array([obs.position], dtype=np.int64),
            goal=np.array([obs.goal], dtype=np.int64),
            nb_cells=nb_cells,
            nb_next=nb_next,
            nb_known=nb_known,
            nb_visible=nb_visible,
        )
