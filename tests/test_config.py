"""Run options: a config written before an option existed reads as the run it started; a value
the messages cannot carry, or a config.json that is not a run's, is refused."""

import json

import pytest

from nnql_swarm.protocol.config import PRESETS, SwarmConfig
from nnql_swarm.protocol.keys import MAX_TICK
from nnql_swarm.protocol.messages import (
    MAX_AGENTS, MAX_REWARD, WORLD_SENDER, Observation, Rejected, encode, parse,
)


def test_a_config_written_before_the_wait_rule_existed_keeps_waiting_for_all_in_reach():
    """A run resumed from an older ``config.json`` plays on as it started: the ``meet`` rule
    came later, and until then every higher-ranked neighbour in reach was waited for."""
    data = json.loads(SwarmConfig().to_json())
    assert data["wait_rule"] == "meet" and SwarmConfig.from_json(json.dumps(data)).meet_only
    del data["wait_rule"], data["identity"]  # (written before runs carried an identity too)
    assert SwarmConfig.from_json(json.dumps(data)).wait_rule == "reach"
    assert PRESETS["nnql"]["wait_rule"] == "reach"  # the paper's hierarchy
    with pytest.raises(ValueError, match="wait rule"):
        SwarmConfig(wait_rule="near")


# ---------------------------------------------------------------- the wire's bounds, once

@pytest.mark.parametrize("field, value", [
    ("goal_reward", float("nan")), ("goal_reward", 1e300), ("goal_reward", -float("inf")),
    ("stay_reward", float("inf")), ("stay_reward", float("nan")),
    ("optimistic", 1e300), ("optimistic", float("nan")), ("tick_deadline_s", float("inf")),
    ("max_steps", 10**17), ("episodes", 10**17), ("n_agents", MAX_AGENTS + 1),
])
def test_a_value_the_messages_cannot_carry_is_refused(field, value):
    with pytest.raises(ValueError):
        SwarmConfig(**{field: value})


def test_the_bounds_are_the_codecs_own():
    """A reward or Q-value at the codec's bound makes a run whose messages parse; beyond it the
    config refuses what the codec would."""
    at_bound = SwarmConfig(goal_reward=MAX_REWARD * (1 - SwarmConfig().gamma))
    assert at_bound.q_bound() == pytest.approx(MAX_REWARD)
    obs = Observation(run="r", tick=0, sender=WORLD_SENDER, agent=0, episode=0, step=0,
                      position=(0, 0), goal=(1, 1), neighbours=b"", rank=0,
                      reward_ds=at_bound.goal_reward, reward_ca=0.0, collided=False,
                      arrived=True, episode_end=False)
    assert parse(encode(obs), Observation, "r").reward_ds == at_bound.goal_reward
    beyond = obs.__class__(**{**{f: getattr(obs, f) for f in obs.__struct_fields__},
                              "reward_ds": MAX_REWARD * 2})
    with pytest.raises(Rejected):
        parse(encode(beyond), Observation, "r")
    with pytest.raises(ValueError, match="goal reward"):
        SwarmConfig(goal_reward=MAX_REWARD * 2)
    with pytest.raises(ValueError, match="Q-values may reach"):
        SwarmConfig(goal_reward=MAX_REWARD)  # a reward the wire carries, but not its return
    last = MAX_TICK // 101 - 1
    assert SwarmConfig(episodes=last).episodes == last  # its last tick fits a message
    with pytest.raises(ValueError, match="largest tick"):
        SwarmConfig(episodes=last + 2)


@pytest.mark.parametrize("text", ["[]", "null", "42", '"run"', "{}", '{"run_id": "x"}'])
def test_a_config_that_is_not_a_runs_is_refused(text):
    with pytest.raises(ValueError, match="JSON object|not a run's config"):
        SwarmConfig.from_json(text)


def test_the_runs_identity_is_in_its_config_json_and_tells_runs_of_one_shape_apart():
    config = SwarmConfig(run_id="a", seed=1)
    assert json.loads(config.to_json())["identity"] == config.identity
    assert SwarmConfig.from_json(config.to_json()).identity == config.identity
    assert SwarmConfig(run_id="a", seed=1).identity == config.identity  # the options make it
    assert len({config.identity, SwarmConfig(run_id="a", seed=2).identity,
                SwarmConfig(run_id="b", seed=1).identity}) == 3
