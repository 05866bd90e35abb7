"""The project as installed: one top-level name (``nnql_swarm``), console scripts with ``--version``,
and a swarm that runs from any directory with a foreign ``launch`` package (ROS 2's name) first
on the path."""

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from nnql_swarm.launch.cli import package_version
from tests.swarm_helpers import ROOT

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

BIN = Path(sys.executable).parent
COMMANDS = ("nnql-swarm", "nnql-experiment", "nnql-view", "nnql-faultsim", "nnql-router",
            "nnql-secure")
FOREIGN = ("launch", "agent", "world", "protocol", "sim", "recording")
"""Generic names that other packages use (``launch`` is ROS 2's launch system)."""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("wheel")
    source = out / "source"  # a copy: setuptools builds in the source tree
    shutil.copytree(ROOT, source, ignore=shutil.ignore_patterns(
        ".git", ".venv", "runs", "build", "*.egg-info", "__pycache__", ".pytest_cache"))
    done = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                           "--wheel-dir", str(out), str(source)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    (found,) = out.glob("nnql_swarm-*.whl")
    return found


def test_the_wheel_installs_one_top_level_name_and_the_console_scripts(wheel):
    with zipfile.ZipFile(wheel) as z:
        names = z.namelist()
        entry_points = next(n for n in names if n.endswith("entry_points.txt"))
        scripts = z.read(entry_points).decode()
    top = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert top == {"nnql_swarm"}
    rooms = sorted(p.name for p in (ROOT / "nnql_swarm").iterdir() if p.is_symlink())
    assert rooms == ["agent", "api", "experiment", "launch", "learning", "protocol", "recording",
                     "sim", "transport", "world"]
    for room in rooms:
        assert f"nnql_swarm/{room}/__init__.py" in names, room
    assert not any(n.startswith(("nnql_swarm/tests/", "nnql_swarm/bench/")) for n in names)
    for command in COMMANDS:
        assert f"{command} = nnql_swarm." in scripts, command


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_tells_its_version(command):
    done = subprocess.run([str(BIN / command), "--version"], capture_output=True, text=True,
                          timeout=60, cwd="/")
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == f"{command} (nnql-swarm {package_version()})"
    assert package_version()[0].isdigit()


def test_the_swarm_runs_from_any_directory_with_foreign_packages_first_on_the_path(tmp_path):
    foreign = tmp_path / "foreign"
    for name in FOREIGN:
        (foreign / name).mkdir(parents=True)
        (foreign / name / "__init__.py").write_text(
            f"raise ImportError('the foreign {name} package was imported')\n")
    env = {**os.environ, "PYTHONPATH": str(foreign), "NNQL_LOG": "WARNING"}
    probe = subprocess.run([sys.executable, "-c", "import launch"], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=60)
    assert "the foreign launch package was imported" in probe.stderr  # it is first on the path
    out = tmp_path / "run"
    done = subprocess.run([str(BIN / "nnql-swarm"), "--agents", "4", "--episodes", "2",
                           "--no-record", "--no-progress", "--out", str(out)],
                          env=env, cwd=tmp_path, capture_output=True, text=True, timeout=240,
                          start_new_session=True)
    assert done.returncode == 0, done.stderr
    assert "foreign" not in done.stderr
    assert len((out / "episodes.csv").read_text().splitlines()) == 1 + 2
