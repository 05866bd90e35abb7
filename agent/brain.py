"""One swarm agent's decisions, pure: observation and neighbours' answers in, action out.

The same object runs inside an agent process (``agent.node``) and in the in-process swarm
(``launch.inprocess``), which is what makes the two runs identical for the same seed.

Negotiation (DESIGN §2, the paper's hierarchical way): at every tick each agent has a rank
(``protocol.config.priority_rank``, rotating so nobody always yields). An nnQL agent waits for its
visible higher-ranked neighbours' intents (:meth:`AgentBrain.neighbours_to_ask`; how it learns them
is ``agent.negotiation``'s plan), decides with whatever came back (:meth:`AgentBrain.act`), and
then answers for itself. A neighbour whose intent did not come is read the QL way, from its
current cell. A QL agent asks nobody.
"""

from agent.learning import EpisodeNoise, Hyper
from agent.negotiation import awaited
from agent.single import SingleLearner, Situation
from protocol.actions import STAY, intended_cell_of
from protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from protocol.messages import Observation
from protocol.seeding import AGENT_STREAM, stream_rng


class AgentBrain:
    """A learner of batch one (``agent.single``), its noise, and the episode bookkeeping."""

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        self.agent = agent
        self.config = config
        self.learner = SingleLearner(
            random_step=config.random_step,
            use_intents=config.algo in NEGOTIATING_ALGOS,
            n_neighbours=config.n_agents,
            hyper=Hyper(config.alpha, config.gamma, config.beta),
            with_direction=config.algo == "nnql-dir",
        )
        self.rng = stream_rng(config.seed, AGENT_STREAM, agent)
        self._noise: EpisodeNoise | None = None
        self._noise_episode = -1
        self._prepared: tuple[Observation, Situation, tuple | None] | None = None

    def neighbours_to_ask(self, obs: Observation) -> list[int]:
        """The visible higher-ranked neighbours whose intents this agent decides with (none once
        it has arrived: it stays); ``agent.negotiation`` plans how to learn them."""
        if obs.arrived:
            return []
        return awaited(obs, self.config.n_agents, self.config.algo)

    def prepare(self, obs: Observation) -> None:
        """Work out what the decision on ``obs`` needs that no intent changes; :meth:`act` on
        the same observation then only adds the intents (an agent prepares while it waits)."""
        cells = {j: (x, y) for j, x, y in obs.neighbours}
        situation = self.learner.situation(obs.position, obs.goal, cells)
        if obs.arrived or obs.episode_end:
            self._prepared = (obs, situation, None)
            return
        if self._noise_episode != obs.episode:
            self._noise = EpisodeNoise.draw(self.rng, self.config.max_steps)
            self._noise_episode = obs.episode
        noise = (int(self._noise.random_actions[obs.step]),
                 self._noise.tie_breakers[obs.step].tolist())
        self._prepared = (obs, situation, noise)

    def act(self, obs: Observation, answers: dict[int, int]) -> int:
        """Learn from the last action's rewards and choose this tick's action (STAY if done)."""
        if self._prepared is None or self._prepared[0] is not obs:
            self.prepare(obs)
        _, situation, noise = self._prepared
        self._prepared = None
        learner = self.learner
        learner.record_one(obs.reward_ds, obs.reward_ca, obs.arrived)
        if noise is None:  # arrived, or the episode's end
            learner.finish_one(situation)
            return STAY
        random_action, ties = noise
        return learner.decide_one(situation, self._next_cells(situation.cells, answers),
                                  random_action, ties)

    def _next_cells(self, cells: dict[int, tuple[int, int]],
                    answers: dict[int, int]) -> dict[int, tuple[int, int]]:
        """The cells the answering neighbours announced they are heading for."""
        w, h = self.config.width, self.config.height
        return {j: intended_cell_of(*cells[j], action, w, h) for j, action in answers.items()}
