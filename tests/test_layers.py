"""The rooms' layers (docs/design.md, the contracts of ``[tool.importlinter]`` in pyproject.toml):
every room imports only the rooms below it; ``world`` and ``agent`` never import each other, and
neither they, ``learning`` nor ``protocol`` imports ``launch``, ``sim``, ``recording`` or any
other room above them; the protocol machines (``agent.machine``, ``world.machine``, and
``protocol``'s effects and phase machine) reach no network, file or recording, however
indirectly. The contracts hold for the package as it is, and break on a copy of it with one
import that crosses a layer."""

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.swarm_helpers import ROOT

LINT = Path(sys.executable).parent / "lint-imports"


def lint(cwd: Path, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([str(LINT), str(ROOT / "pyproject.toml"), "--no-cache"],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=120)


def test_the_package_keeps_its_layers(tmp_path):
    done = lint(tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "4 kept, 0 broken" in done.stdout


@pytest.mark.parametrize("module, crossing", [
    ("world/engine.py", "nnql_swarm.agent.brain"),
    ("agent/brain.py", "nnql_swarm.world.rules"),
    ("world/node.py", "nnql_swarm.sim.resume"),
    ("agent/node.py", "nnql_swarm.recording.columns"),
    ("learning/record.py", "nnql_swarm.agent.brain"),
    ("sim/runs.py", "nnql_swarm.launch.swarm_cli"),
    ("protocol/config.py", "nnql_swarm.launch.cli"),
    ("agent/machine.py", "zenoh"),
    ("world/machine.py", "nnql_swarm.transport.runfiles"),
    ("world/records.py", "nnql_swarm.transport.adapter"),
    ("agent/negotiation.py", "nnql_swarm.agent.checkpoint"),
    ("protocol/effects.py", "rerun"),
    ("protocol/phase_machine.py", "nnql_swarm.transport.slotfile"),
    ("world/terrain.py", "nnql_swarm.agent.brain"),
])
def test_an_import_across_the_layers_breaks_a_contract(tmp_path, module, crossing):
    copy = tmp_path / "nnql_swarm"
    shutil.copytree(ROOT / "nnql_swarm", copy,
                    ignore=shutil.ignore_patterns("__pycache__"))  # the rooms' links followed
    path = copy / module
    path.write_text(path.read_text() + f"\nimport {crossing}  # noqa: E402\n")
    done = lint(tmp_path, {"PATH": "/usr/bin:/bin", "PYTHONPATH": str(tmp_path)})
    assert done.returncode == 1, done.stdout + done.stderr
    importer = "nnql_swarm." + module.removesuffix(".py").replace("/", ".")
    assert f"{importer} -> {crossing}" in done.stdout, done.stdout
