"""The rooms' layers (docs/design.md, the contracts of ``[tool.importlinter]`` in pyproject.toml):
every room imports only the rooms below it; ``world`` and ``agent`` never import each other, and
neither they, ``learning`` nor ``protocol`` imports ``launch``, ``sim``, ``recording`` or any
other room above them; the protocol machines (``agent.agent_machine``, ``world.world_machine``, and
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
    ("world/world_node.py", "nnql_swarm.sim.resume"),
    ("agent/agent_node.py", "nnql_swarm.recording.columns"),
    ("learning/record.py", "nnql_swarm.agent.brain"),
    ("sim/runs.py", "nnql_swarm.launch.swarm_cli"),
    ("protocol/config.py", "nnql_swarm.launch.cli"),
    ("agent/agent_machine.py", "zenoh"),
    ("world/world_machine.py", "nnql_swarm.transport.runfiles"),
    ("world/records.py", "nnql_swarm.transport.adapter"),
    ("agent/negotiation.py", "nnql_swarm.agent.agent_checkpoint"),
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


def test_every_module_of_the_package_has_a_name_no_other_room_uses():
    """A file's name says what it is wherever it is quoted: no two rooms hold a ``node.py``."""
    from collections import defaultdict

    rooms: dict[str, list[str]] = defaultdict(list)
    for room in sorted(p for p in (ROOT / "nnql_swarm").iterdir() if p.is_dir()):
        for module in room.glob("*.py"):
            if module.name != "__init__.py":
                rooms[module.name].append(room.name)
    assert len(rooms) > 100
    assert {name: where for name, where in rooms.items() if len(where) > 1} == {}
