"""The PettingZoo adapter: the library's API, seed and render tests, and the world rules seen
through it."""

from pathlib import Path

import numpy as np
import pytest
import rerun as rr
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, render_test
from pettingzoo.utils.conversions import parallel_to_aec

from nnql_swarm.protocol.actions import LEFT, N_STATES, RIGHT, STAY, UP, offset_state
from nnql_swarm.api.pettingzoo_env import NOT_IN_VIEW, SwarmGridEnv
from nnql_swarm.world.rules import CA_REWARD, GOAL_REWARD
from nnql_swarm.recording.palette import agent_colors


@pytest.mark.filterwarnings("error::UserWarning")  # the API test reports problems as warnings
@pytest.mark.parametrize("n_agents, size, count_swaps", [(1, 5, True), (4, 11, True), (6, 7, False)])
def test_parallel_api(n_agents, size, count_swaps):
    env = SwarmGridEnv(n_agents=n_agents, width=size, height=size, max_steps=40, count_swaps=count_swaps)
    parallel_api_test(env, num_cycles=200)


def test_parallel_seed():
    parallel_seed_test(lambda: SwarmGridEnv(n_agents=5, max_steps=60), num_cycles=200)


# The API test suggests Box or Discrete observations; the paper's states are MultiDiscrete.
@pytest.mark.filterwarnings("ignore:Observation space for each agent probably should be")
@pytest.mark.filterwarnings("error::UserWarning")
def test_aec_api_of_the_parallel_env():
    api_test(parallel_to_aec(SwarmGridEnv(n_agents=4, max_steps=40)), num_cycles=200)


def test_render_test_passes_in_every_mode_without_a_display(monkeypatch):
    monkeypatch.setattr("sys.platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    made = []

    def env_fn(render_mode=None):
        made.append(SwarmGridEnv(n_agents=4, max_steps=30, render_mode=render_mode))
        return parallel_to_aec(made[-1])

    with pytest.warns(RuntimeWarning, match="without a display"):
        render_test(env_fn)
    human = [env for env in made if env.render_mode == "human" and env.rerun_memory is not None]
    assert human and human[-1].rerun_memory.num_msgs() > 0  # the frames, kept in memory


def rollout(env: SwarmGridEnv, seed: int, policy_seed: int) -> list:
    """Every (observations, rewards, terminations, truncations, infos) of one seeded episode."""
    observations, _ = env.reset(seed=seed)
    rng = np.random.default_rng(policy_seed)
    trace = [observations]
    while env.agents:
        actions = {agent: int(rng.integers(5)) for agent in env.agents}
        trace.append(env.step(actions))
    return trace


def same(a, b) -> bool:
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return np.array_equal(a, b)


def test_same_seed_same_trajectory_and_other_seed_another():
    first = rollout(SwarmGridEnv(n_agents=4, max_steps=50), seed=7, policy_seed=1)
    again = rollout(SwarmGridEnv(n_agents=4, max_steps=50), seed=7, policy_seed=1)
    other = rollout(SwarmGridEnv(n_agents=4, max_steps=50), seed=8, policy_seed=1)
    assert same(first, again)
    assert not same(first, other)


def test_reset_without_seed_moves_on_to_the_next_episode_of_the_seed():
    env = SwarmGridEnv(n_agents=3)
    first, _ = env.reset(seed=3)
    second, _ = env.reset()
    assert not same(first, second)
    again, _ = env.reset(seed=3)
    assert same(first, again)


def place(env: SwarmGridEnv, positions, goals) -> None:
    """Start the env's episode on hand-made starts and goals (``reset``'s options)."""
    env.reset(seed=0, options={"starts": positions, "goals": goals})


def test_observation_holds_goal_offset_and_neighbour_offsets():
    env = SwarmGridEnv(n_agents=3, width=15, height=15)
    env.reset(seed=0)
    place(env, [(0, 0), (2, 1), (14, 0)], [(3, 4), (9, 9), (10, 10)])
    observation = env._observe(0)
    assert observation.tolist() == [offset_state(3, 4), offset_state(2, 1), NOT_IN_VIEW]
    assert env.observation_space("agent_0").contains(observation)
    assert env.observation_space("agent_0").nvec.tolist() == [N_STATES, N_STATES + 1, N_STATES + 1]


def test_rewards_collisions_arrival_and_removal():
    env = SwarmGridEnv(n_agents=3, width=5, height=5, count_swaps=True)
    # agent_0 steps onto its goal; agent_1 and agent_2 try to swap cells.
    place(env, [(0, 0), (3, 3), (4, 3)], [(1, 0), (0, 4), (4, 0)])
    _, rewards, terminations, truncations, infos = env.step({"agent_0": RIGHT, "agent_1": RIGHT, "agent_2": LEFT})
    assert rewards["agent_0"] == pytest.approx(GOAL_REWARD + CA_REWARD)
    assert terminations == {"agent_0": True, "agent_1": False, "agent_2": False}
    assert not any(truncations.values())
    assert infos["agent_1"]["collided"] and infos["agent_2"]["collided"]
    assert infos["agent_1"]["reward_ca"] == 0.0
    # Staying put: same distance, 0.5 / d.
    assert infos["agent_1"]["reward_ds"] == pytest.approx(0.5 / np.hypot(3, 1))
    assert env.agents == ["agent_1", "agent_2"]
    # The arrived agent stays on its goal, and running into it is a collision.
    for _ in range(2):
        _, _, _, _, infos = env.step({"agent_1": UP, "agent_2": STAY})
    _, _, _, _, infos = env.step({"agent_1": LEFT, "agent_2": STAY})  # (3, 1) to (2, 1)
    _, _, _, _, infos = env.step({"agent_1": LEFT, "agent_2": STAY})  # to (1, 1)
    assert (env._x[1], env._y[1]) == (1, 1)
    _, _, _, _, infos = env.step({"agent_1": UP, "agent_2": STAY})  # into agent_0 on (1, 0)
    assert infos["agent_1"]["collided"] and "agent_0" not in infos
    assert (env._x[0], env._y[0]) == (1, 0) and (env._x[1], env._y[1]) == (1, 1)


def test_infos_name_whom_each_agent_waits_for():
    env = SwarmGridEnv(n_agents=3, width=8, height=8, negotiation_radius=2)
    env.reset(seed=0)
    place(env, [(0, 0), (1, 1), (6, 6)], [(7, 7), (7, 0), (0, 7)])
    _, _, _, _, infos = env.step({a: STAY for a in env.agents})
    # After one step the ranks are (i - 1) mod 3: agent 1 leads, agent 0 is in its reach.
    assert infos["agent_0"]["waits_for"] == ["agent_1"]
    assert infos["agent_1"]["waits_for"] == [] and infos["agent_2"]["waits_for"] == []


def test_infos_under_the_meet_rule_leave_out_a_neighbour_it_cannot_meet():
    for rule, expected in (("reach", ["agent_1"]), ("meet", [])):
        env = SwarmGridEnv(n_agents=2, width=8, height=8, negotiation_radius=2, wait_rule=rule)
        env.reset(seed=0)
        place(env, [(0, 0), (2, 2)], [(7, 7), (7, 0)])
        _, _, _, _, infos = env.step({a: STAY for a in env.agents})
        assert infos["agent_0"]["waits_for"] == expected  # two cells off along both axes
    with pytest.raises(ValueError, match="wait rule"):
        SwarmGridEnv(wait_rule="near")


def test_truncation_after_max_steps():
    env = SwarmGridEnv(n_agents=2, max_steps=3)
    env.reset(seed=1)
    for _ in range(2):
        _, _, terminations, truncations, _ = env.step({a: STAY for a in env.agents})
        assert not any(truncations.values())
    _, _, terminations, truncations, _ = env.step({a: STAY for a in env.agents})
    assert all(truncations.values()) and not any(terminations.values())
    assert env.agents == []


def test_ansi_render_draws_agents_and_goals():
    env = SwarmGridEnv(n_agents=2, width=4, height=3, render_mode="ansi")
    env.reset(seed=0)
    place(env, [(0, 0), (3, 2)], [(1, 0), (0, 2)])
    assert env.render() == "Aa..\n....\nb..B"


def test_too_many_agents_for_the_grid_is_refused():
    with pytest.raises(ValueError, match="distinct start and goal cells"):
        SwarmGridEnv(n_agents=5, width=3, height=3)


def test_the_env_takes_the_swarms_config():
    """``SwarmGridEnv(swarm.config)``: the swarm's agents, grid, steps, rewards and waits, the
    same values, not restated; what the env does not play is refused in one line."""
    from nnql_swarm.api import Swarm

    swarm = Swarm(agents=5, grid=(9, 7), max_steps=30, goal_reward=4.0, stay_reward=0.25,
                  radius=3, wait_rule="meet", count_swaps=False)
    env = SwarmGridEnv(swarm.config)
    assert env.config is swarm.config
    assert (env.n_agents, env.width, env.height, env.max_steps, env.count_swaps,
            env.negotiation_radius, env.meet_only) == (5, 9, 7, 30, False, 3, True)
    assert SwarmGridEnv(n_agents=5, grid=(9, 7), max_steps=30, goal_reward=4.0,
                        stay_reward=0.25, radius=3, wait_rule="meet",
                        count_swaps=False).config.learning() != swarm.config.learning()
    env.reset(seed=0)
    place(env, [(0, 0), (8, 6), (4, 0), (0, 6), (8, 0)],
          [(1, 0), (8, 5), (4, 2), (0, 5), (7, 0)])
    _, rewards, terminations, _, infos = env.step(
        {"agent_0": RIGHT, "agent_1": UP, "agent_2": STAY, "agent_3": UP, "agent_4": LEFT})
    assert terminations["agent_0"] and infos["agent_0"]["reward_ds"] == 4.0
    assert infos["agent_2"]["reward_ds"] == 0.25 / 2  # stayed, two cells from its goal
    assert SwarmGridEnv().config.n_agents == Swarm().config.n_agents  # the config's defaults
    with pytest.raises(ValueError, match="not both"):
        SwarmGridEnv(swarm.config, n_agents=3)


def test_rgb_array_draws_goals_and_agents_in_their_colours():
    env = SwarmGridEnv(n_agents=2, width=4, height=3, render_mode="rgb_array", cell_pixels=10)
    env.reset(seed=0)
    place(env, [(0, 0), (3, 2)], [(1, 0), (0, 2)])
    image = env.render()
    assert image.shape == (30, 40, 3) and image.dtype == np.uint8
    colors = agent_colors(2)
    assert (image[5, 5] == colors[0]).all() and (image[25, 35] == colors[1]).all()  # agents
    assert (image[1, 10 + 5] == colors[0]).all()  # agent 0's goal: an outline, hollow
    assert (image[5, 15] == 255).all()
    assert (image[20 + 1, 5] == colors[1]).all()
    assert (image[15, 25] == 255).all()  # a free cell
    assert (image[0, :] == 200).all() and (image[:, 10] == 200).all()  # grid lines


def test_human_saves_its_frames_to_a_recording(tmp_path):
    path = tmp_path / "frames.rrd"
    env = SwarmGridEnv(n_agents=3, render_mode="human", rerun=path)
    env.reset(seed=2)
    for _ in range(4):
        assert env.render() is None
        env.step({agent: STAY for agent in env.agents})
    env.close()
    reader = rr.chunk.RrdReader(path)
    steps = sorted({step for chunk in reader.stream()
                    if chunk.entity_path.lstrip("/") == "world/agents" and not chunk.is_static
                    for step in chunk.to_record_batch().column("step").to_pylist()})
    assert steps == [0, 1, 2, 3]


def test_human_draws_every_agents_goal(tmp_path):
    """Rerun draws a box per half-size given: every goal needs its own."""
    path = tmp_path / "frames.rrd"
    env = SwarmGridEnv(n_agents=8, render_mode="human", rerun=path)
    env.reset(seed=4)
    env.render()
    env.close()
    [batch] = [chunk.to_record_batch() for chunk in rr.chunk.RrdReader(path).stream()
               if chunk.entity_path.lstrip("/") == "world/goals" and not chunk.is_static]
    [centres] = batch.column("Boxes2D:centers").to_pylist()
    [half_sizes] = batch.column("Boxes2D:half_sizes").to_pylist()
    goals = sorted(zip(env._goal_x, env._goal_y))
    assert sorted(tuple(round(v) for v in centre) for centre in centres) == goals
    assert len(half_sizes) == len(goals) == 8


def test_rgb_array_draws_every_agents_goal():
    env = SwarmGridEnv(n_agents=8, render_mode="rgb_array", cell_pixels=10)
    env.reset(seed=4)
    image = env.render()
    colors = agent_colors(8)
    for i, (x, y) in enumerate(zip(env._goal_x, env._goal_y)):
        assert (image[y * 10 + 1, x * 10 + 5] == colors[i]).all(), f"agent {i}'s goal"


def test_an_unknown_render_mode_is_refused():
    with pytest.raises(ValueError, match="render mode"):
        SwarmGridEnv(render_mode="rgb")


MAZE = Path(__file__).resolve().parents[1] / "maps" / "maze-19x19-s0.map"


def test_the_env_plays_a_map_file_and_never_enters_a_wall():
    """``map=``: the swarm's map, its walls drawn in every mode, and nobody ever on one."""
    env = SwarmGridEnv(n_agents=6, map=str(MAZE), max_steps=40, render_mode="ansi")
    walls = {tuple(cell) for cell in env.config.walls().tolist()}
    assert walls and (env.width, env.height) == (19, 19)
    env.reset(seed=3)
    text = env.render().splitlines()
    assert {(x, y) for y, row in enumerate(text) for x, ch in enumerate(row) if ch == "#"} == walls
    rng = np.random.default_rng(0)
    while env.agents:
        env.step({agent: int(rng.integers(5)) for agent in env.agents})
        assert not walls & set(zip(env._x, env._y))
    picture = SwarmGridEnv(n_agents=6, map=str(MAZE), render_mode="rgb_array", cell_pixels=8)
    picture.reset(seed=3)
    x, y = next(iter(walls))
    assert (picture.render()[y * 8 + 4, x * 8 + 4] == 60).all()


def test_lifelong_hands_out_the_next_goal_and_nobody_is_terminated():
    env = SwarmGridEnv(n_agents=2, width=6, height=6, tasks="lifelong", max_steps=5)
    place(env, [(0, 0), (5, 5)], [(1, 0), (5, 3)])
    _, rewards, terminations, truncations, infos = env.step({"agent_0": RIGHT, "agent_1": STAY})
    assert infos["agent_0"]["reached"] and not infos["agent_1"]["reached"]
    assert rewards["agent_0"] == pytest.approx(GOAL_REWARD + CA_REWARD)
    assert (env._goal_x[0], env._goal_y[0]) != (1, 0)  # its next goal, already
    assert env.agents == ["agent_0", "agent_1"] and not any(terminations.values())
    for _ in range(4):
        _, _, terminations, truncations, _ = env.step({a: STAY for a in env.agents})
    assert all(truncations.values()) and not any(terminations.values()) and env.agents == []


def test_under_step_aside_all_are_terminated_together():
    env = SwarmGridEnv(n_agents=2, width=6, height=6, on_target="step-aside")
    place(env, [(0, 0), (5, 5)], [(1, 0), (5, 4)])
    _, _, terminations, _, _ = env.step({"agent_0": RIGHT, "agent_1": STAY})
    assert not any(terminations.values()) and env.agents == ["agent_0", "agent_1"]
    _, _, terminations, _, _ = env.step({"agent_0": STAY, "agent_1": UP})
    assert all(terminations.values()) and env.agents == []
