"""The swarm's kernels compiled ahead of time (``learning.ahead``: the agents' decision, negotiation
plan and neighbour rows, the world's check of a learning record; ``world.rules_ahead``: the world's
step and its arbitration by priority inheritance): built once into the kernel cache, even by several processes at once; loaded by a process that
runs the kernels in plain Python, without numba; and deciding, planning, checking and moving
everyone exactly as plain Python does, over the real handlers of a whole run."""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import pytest

from nnql_swarm.learning import ahead
from nnql_swarm.protocol.config import DEFAULT_PRESET
from nnql_swarm.protocol.jit import cache_directory
from nnql_swarm.world.rules_ahead import RULES

PROBE = ("import sys; from nnql_swarm.learning import ahead; "
         "from nnql_swarm.world.rules_ahead import RULES; "
         "print(ahead.KERNELS.compiled('agent_decision')[1]); "
         "print(RULES.compiled('world_move')[1]); "
         "print(RULES.compiled('pibt_plan')[1]); "
         "print('numba' in sys.modules)")

RUN = """
import hashlib, sys
from pathlib import Path
from bench import node_cpu
from bench.harness import swarm_config
from nnql_swarm.learning import ahead
from nnql_swarm.world.rules_ahead import RULES
config = swarm_config(sys.argv[2], run_id="ahead", n_agents=8, episodes=8, max_steps=100,
                      width=11, height=11)
wire = hashlib.sha256()
def on_send(number, kind, sender, receiver, item, cause):
    payload = getattr(item, "payload", b"")
    wire.update(repr((number, kind, sender, receiver)).encode() + bytes(payload))
ticks, _ = node_cpu.run(config, Path(sys.argv[1]), False, on_send=on_send)
print(ticks, wire.hexdigest(), ahead.KERNELS.compiled("agent_decision")[1],
      RULES.compiled("world_move")[1], RULES.compiled("pibt_plan")[1])
"""


def plain(env: dict[str, str]) -> dict[str, str]:
    return {**os.environ, **env, "NNQL_KERNEL": "python"}


def checkpoints(out: Path) -> str:
    """A digest of a run's checkpoints (every agent's tables, known walls, counts)."""
    digest = hashlib.sha256()
    for path in sorted((out / "checkpoints").rglob("*")):
        if path.is_file():
            digest.update(path.name.encode() + path.read_bytes())
    return digest.hexdigest()


@pytest.fixture(scope="module")
def built() -> Path:
    """The modules of these kernel sources, built if missing (as the launcher does)."""
    assert RULES.ensure(), "the world's step could not be compiled ahead of time"
    assert ahead.KERNELS.ensure(), "the agents' decision could not be compiled ahead of time"
    return ahead.KERNELS.path()


def test_a_plain_process_loads_the_built_decision_without_numba(built):
    done = subprocess.run([sys.executable, "-c", PROBE], env=plain({}), capture_output=True,
                          text=True, timeout=120)
    assert done.stdout.split() == [ahead.AHEAD] * 3 + ["False"], done.stderr


def test_without_the_module_or_with_it_switched_off_a_process_decides_in_plain_python(
        built, tmp_path):
    for env in ({ahead.SWITCH: "off"}, {"XDG_CACHE_HOME": str(tmp_path / "no-cache")}):
        done = subprocess.run([sys.executable, "-c", PROBE], env=plain(env),
                              capture_output=True, text=True, timeout=120)
        assert done.stdout.split() == [ahead.PLAIN] * 3 + ["False"], (env, done.stderr)


@pytest.mark.parametrize("preset", [DEFAULT_PRESET, "pibt-nnql"])
def test_the_decision_compiled_ahead_of_time_decides_as_plain_python_does(built, tmp_path,
                                                                          preset):
    """The real handlers of a whole run (``bench.node_cpu``: the world and 8 agents in one
    process, every message delivered in order), once with the kernels compiled ahead of time and
    once in plain Python: the same ticks, every message the same (a record the world's check
    refused would change the table's updates it sends), the same checkpoints (the agents' tables
    among them), bit for bit; by default and under priority inheritance (``pibt-nnql``: the
    world's arbitration compiled too)."""
    runs = {}
    for how, env in ((ahead.AHEAD, {}), (ahead.PLAIN, {ahead.SWITCH: "off"})):
        out = tmp_path / how
        done = subprocess.run([sys.executable, "-c", RUN, str(out), preset], env=plain(env),
                              capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        ticks, messages, decided, moved, arbitrated = done.stdout.split()
        assert decided == moved == arbitrated == how and int(ticks) > 8
        runs[how] = (ticks, messages, checkpoints(out))
    assert runs[ahead.AHEAD] == runs[ahead.PLAIN]


@pytest.mark.full
def test_processes_that_build_at_once_build_one_module_into_a_fresh_cache(tmp_path):
    """Into an empty cache (``XDG_CACHE_HOME``; numba's own cache of compiled kernels kept), two
    builders at once: both succeed, one module results, and a plain process decides with it
    (and moves and arbitrates in plain Python: the world's module was not built)."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path), "NNQL_KERNEL": "compiled",
           "NUMBA_CACHE_DIR": str(cache_directory())}
    builders = [subprocess.Popen([sys.executable, "-m", "nnql_swarm.learning.ahead"], env=env,
                                 stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                for _ in range(2)]
    outputs = [builder.communicate(timeout=600) for builder in builders]
    assert [builder.returncode for builder in builders] == [0, 0], outputs
    built = {Path(stdout.strip()) for stdout, _ in outputs}
    assert len(built) == 1 and next(iter(built)).is_relative_to(tmp_path), outputs
    assert [p.name for p in next(iter(built)).parent.iterdir() if p.suffix == ".so"] \
        == [next(iter(built)).name]
    done = subprocess.run([sys.executable, "-c", PROBE], env=plain({"XDG_CACHE_HOME":
                                                                    str(tmp_path)}),
                          capture_output=True, text=True, timeout=120)
    assert done.stdout.split() == [ahead.AHEAD, ahead.PLAIN, ahead.PLAIN, "False"], done.stderr


@pytest.mark.full
def test_a_build_that_fails_is_said_once_and_leaves_the_agents_deciding_in_plain_python(
        tmp_path):
    """Where the C compiler fails (``CC=false``), the launcher's build says why in a warning,
    notes the failure in the cache, and no later process tries again: they decide in plain
    Python."""
    ensure = ("import logging, sys; logging.basicConfig(); from nnql_swarm.learning import ahead; "
              "print(ahead.KERNELS.ensure(), ahead.KERNELS.compiled('agent_decision')[1])")
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path), "NNQL_KERNEL": "python", "CC": "false",
           "NUMBA_CACHE_DIR": str(cache_directory())}
    first = subprocess.run([sys.executable, "-c", ensure], env=env, capture_output=True,
                           text=True, timeout=600)
    assert first.stdout.split() == ["False", ahead.PLAIN], first.stderr
    assert "Compiling the agents' and the world's kernels" in first.stderr
    assert "could not be compiled ahead of time" in first.stderr
    failed = list(tmp_path.rglob("*.failed"))
    assert len(failed) == 1 and failed[0].read_text().strip()
    again = subprocess.run([sys.executable, "-c", ensure], env=env, capture_output=True,
                           text=True, timeout=60)
    assert again.stdout.split() == ["False", ahead.PLAIN], again.stderr
    assert "Compiling" not in again.stderr and "could not" not in again.stderr
