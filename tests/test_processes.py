"""How the swarm's processes start: forked from a server that holds what an agent runs and no
more (``launch.processes.process_context``), real processes."""

import json
import os
import subprocess
import sys

import pytest

from tests.swarm_helpers import ROOT

WORLD_ONLY = ("nnql_swarm.world.world_node", "nnql_swarm.world.engine", "nnql_swarm.launch.cli",
              "tqdm", "rerun")
"""Modules the world (or a recording process) runs and an agent does not."""


@pytest.mark.full
def test_a_forked_process_holds_none_of_the_worlds_modules_and_the_launchers_main_once():
    """And its collections never walk what it inherited: the server froze it."""
    done = subprocess.run([sys.executable, "-m", "tests.forked_modules",
                           "nnql_swarm.agent.agent_node", *WORLD_ONLY],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    child = json.loads(done.stdout.splitlines()[-1])
    assert child["held"] == ["nnql_swarm.agent.agent_node"]
    assert not child["main_run_again"]  # the server ran it as its __main__: the child did not
    assert child["frozen"] > 10_000


@pytest.mark.full
def test_a_forked_process_finds_a_launcher_run_from_its_path_run_by_the_server():
    """A launcher run from its path (``launch/swarm.py``) is run once by the server, not again by
    each child: its source is compiled once (no ``.pyc`` is written here)."""
    done = subprocess.run([sys.executable, str(ROOT / "tests" / "forked_modules.py")],
                          cwd=ROOT, capture_output=True, text=True, timeout=120,
                          env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert done.returncode == 0, done.stderr
    child = json.loads(done.stdout.splitlines()[-1])
    assert not child["main_run_again"]
