"""Run options: a config written before an option existed reads as the run it started."""

import json

import pytest

from nnql_swarm.protocol.config import PRESETS, SwarmConfig


def test_a_config_written_before_the_wait_rule_existed_keeps_waiting_for_all_in_reach():
    """A run resumed from an older ``config.json`` plays on as it started: the ``meet`` rule
    came later, and until then every higher-ranked neighbour in reach was waited for."""
    data = json.loads(SwarmConfig().to_json())
    assert data["wait_rule"] == "meet" and SwarmConfig.from_json(json.dumps(data)).meet_only
    del data["wait_rule"]
    assert SwarmConfig.from_json(json.dumps(data)).wait_rule == "reach"
    assert PRESETS["nnql"]["wait_rule"] == "reach"  # the paper's hierarchy
    with pytest.raises(ValueError, match="wait rule"):
        SwarmConfig(wait_rule="near")
