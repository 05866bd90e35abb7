"""The agent's batch-of-one learner (agent.single) against the batch Learners it stands in for.

Two swarms run side by side from one config: one with AgentBrain (SingleLearner), one with a
reference brain that drives the batch ``Learners`` through a ``View``, as the agent did before.
Every action, every table entry and every pending transition must be equal, bit for bit.
"""

import numpy as np
import pytest

from agent.brain import AgentBrain
from agent.learning import Hyper, Learners, View
from protocol.actions import STAY, intended_cell
from protocol.config import NEGOTIATING_ALGOS, SwarmConfig
from world.engine import SwarmWorld


class ReferenceBrain(AgentBrain):
    """AgentBrain's decisions made by the batch code path (Learners over a View of batch 1)."""

    def __init__(self, agent: int, config: SwarmConfig) -> None:
        super().__init__(agent, config)
        self.learner = Learners(
            random_step=np.array([config.random_step]),
            use_intents=np.array([config.algo in NEGOTIATING_ALGOS]),
            n_neighbours=config.n_agents,
            hyper=Hyper(config.alpha, config.gamma, config.beta),
            with_direction=np.array([config.algo == "nnql-dir"]),
        )

    def act(self, obs, answers):
        self.learner.record(np.array([obs.reward_ds]), np.array([obs.reward_ca]),
                            np.array([obs.arrived]))
        view = self._view(obs, answers)
        if obs.arrived or obs.episode_end:
            self.learner.finish(np.array([True]), view)
            return STAY
        noise = self._episode_noise(obs)
        return int(self.learner.decide(view, np.array([True]),
                                       noise.random_actions[obs.step: obs.step + 1],
                                       noise.tie_breakers[obs.step: obs.step + 1])[0])

    def _episode_noise(self, obs):
        from agent.learning import EpisodeNoise

        if self._noise_episode != obs.episode:
            self._noise = EpisodeNoise.draw(self.rng, self.config.max_steps)
            self._noise_episode = obs.episode
        return self._noise

    def _view(self, obs, answers) -> View:
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
        return View(np.array([obs.position]), np.array([obs.goal]), nb_cells, nb_next,
                    nb_known, nb_visible)


def run_swarm(config: SwarmConfig, brain_class) -> tuple[list, list]:
    world = SwarmWorld(config)
    brains = [brain_class(i, config) for i in range(config.n_agents)]
    actions_by_tick = []
    while not world.finished:
        actions: dict[int, int] = {}
        for obs in sorted(world.observations(), key=lambda o: o.rank):
            brain = brains[obs.agent]
            answers = {j: actions[j] for j in brain.neighbours_to_ask(obs)}
            actions[obs.agent] = brain.act(obs, answers)
        ordered = [actions[i] for i in range(config.n_agents)]
        actions_by_tick.append(ordered)
        world.apply(ordered)
    return actions_by_tick, brains


@pytest.mark.parametrize("algo,grid,agents", [
    ("nnql", (11, 11), 8), ("ql", (11, 11), 8), ("nnql-dir", (11, 11), 6),
    ("nnql", (30, 12), 10),  # some agents out of each other's view
])
def test_single_learner_is_the_batch_learner_bit_for_bit(algo, grid, agents):
    config = SwarmConfig(run_id="single", n_agents=agents, episodes=12, max_steps=60,
                         width=grid[0], height=grid[1], algo=algo, random_step=5, seed=3)
    fast_actions, fast = run_swarm(config, AgentBrain)
    reference_actions, reference = run_swarm(config, ReferenceBrain)
    assert fast_actions == reference_actions
    assert len({tuple(a) for a in fast_actions}) > 10, "the swarm should do something"
    for a, b in zip(fast, reference):
        for name in ("q_ds", "q_ca", "actions_taken"):
            assert np.array_equal(getattr(a.learner, name), getattr(b.learner, name)), name
        for name, pending in a.learner.pending_as_batch().items():
            assert np.array_equal(pending, getattr(b.learner, name)), name
        assert np.any(a.learner.q_ca != 0)


def test_intended_cell_of_is_intended_cell_for_one_cell():
    from protocol.actions import N_ACTIONS, intended_cell_of

    for x in range(-1, 6):
        for y in range(-1, 5):
            for action in range(N_ACTIONS):
                expected = tuple(intended_cell(np.array([x, y]), action, 5, 4).tolist())
                assert intended_cell_of(x, y, action, 5, 4) == expected


def test_offset_state_of_is_offset_state_for_one_offset():
    from protocol.actions import offset_state, offset_state_of

    for dx in range(-14, 15):
        for dy in range(-14, 15):
            assert offset_state_of(dx, dy) == int(offset_state(np.array([dx, dy])))


def test_sum_like_einsum_adds_as_einsum_does_bit_for_bit():
    """Eq. 6's sum: if numpy ever sums ``bm,bma->ba`` in another order, this fails rather than
    the agent processes drifting from the batch learner (and from the in-process swarm)."""
    from agent.single import sum_like_einsum

    rng = np.random.default_rng(7)
    for slots in (1, 2, 7, 8, 9, 16, 33):
        for _ in range(300):
            weights = rng.random(slots) * (rng.random(slots) < 0.8)
            rows = rng.normal(size=(slots, 5)) * 10.0 ** rng.integers(-3, 4, size=(slots, 5))
            expected = np.einsum("bm,bma->ba", weights[None], rows[None])[0].tolist()
            visible = [(m, float(w)) for m, w in enumerate(weights) if w != 0.0]
            assert sum_like_einsum(visible, rows.tolist(), list(range(slots))) == expected
