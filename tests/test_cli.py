"""What a person sees at the command line: one line and exit code 2 for an unusable ``--out``,
commands that name themselves as they were called, the command that continues a run, and a word
before the simulator compiles."""

import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nnql_swarm.launch.swarm_cli import build_parser, resume_command
from nnql_swarm.protocol.config import SwarmConfig
from nnql_swarm.sim import runs
from nnql_swarm.sim.capacity import available_bytes, check_fits
from nnql_swarm.sim.runs import compiled_simulator, swarm_world
from nnql_swarm.launch.cli import COMPILING, prepare_simulator, report_written
from tests.swarm_helpers import ROOT

BIN = Path(sys.executable).parent
SWARM = ROOT / "launch" / "swarm.py"
EXPERIMENT = ROOT / "launch" / "experiment.py"


def one_line_exit_2(done: subprocess.CompletedProcess, message: str) -> None:
    assert done.returncode == 2, done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], done.stderr
    assert "Traceback" not in done.stderr


def unusable_out(tmp_path: Path, kind: str) -> tuple[Path, str]:
    """An ``--out`` no run can go to, and the words of its refusal."""
    if kind == "file":
        path = tmp_path / "a-file"
        path.write_text("not a folder\n")
        return path, "is a file"
    if kind == "other files":
        path = tmp_path / "photos"
        path.mkdir()
        (path / "holiday.jpg").write_bytes(b"\xff\xd8")
        return path, "holds other files (holiday.jpg)"
    return Path(kind), "cannot make"


@pytest.mark.parametrize("kind", ["/proc/x", "/dev/null/x", "file", "other files"])
def test_an_unusable_out_gives_one_line_and_exit_2(tmp_path, kind):
    out, message = unusable_out(tmp_path, kind)
    before = sorted(p.name for p in out.iterdir()) if out.is_dir() else None
    done = subprocess.run([sys.executable, str(SWARM), "--out", str(out), "--agents", "2",
                           "--episodes", "1", "--no-progress"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    one_line_exit_2(done, message)
    if before is not None:
        assert sorted(p.name for p in out.iterdir()) == before  # nothing written into it


def test_a_folder_with_a_run_that_finished_no_episode_is_taken(tmp_path):
    out = tmp_path / "started"
    (out / "rerun-parts").mkdir(parents=True)  # e.g. the agents of this host, started first
    (out / "config.json").write_text("{}\n")
    done = subprocess.run([sys.executable, str(SWARM), "--out", str(out), "--agents", "2",
                           "--episodes", "1", "--max-steps", "5", "--grid", "5x5",
                           "--no-progress", "--no-record"],
                          cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert (out / "episodes.csv").exists()


@pytest.mark.parametrize("command", [[], ["swarm"]])
@pytest.mark.parametrize("kind", ["/proc/x", "/dev/null/x", "file"])
def test_the_experiments_refuse_an_unusable_out_before_simulating(tmp_path, command, kind):
    out, _ = unusable_out(tmp_path, kind)
    done = subprocess.run([sys.executable, str(EXPERIMENT), *command, "--out", str(out),
                           "--no-plots", "--episodes", "5", "--seeds", "1"],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    one_line_exit_2(done, str(out))


def help_of(*command: str) -> str:
    done = subprocess.run([*command, "--help"], capture_output=True, text=True, timeout=60, cwd="/")
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize("elapsed, took", [(0.0334, "33 ms"), (0.9994, "999 ms"),
                                            (1.0, "1.0 s"), (85.66, "85.7 s")])
def test_an_experiment_ends_saying_where_it_wrote_and_how_long_it_simulated(capsys, elapsed,
                                                                             took):
    """A small run of the compiled simulator takes milliseconds: it is not said to take 0.0 s."""
    report_written(Path("runs/x"), elapsed)
    assert capsys.readouterr().out == f"wrote runs/x/ in {took} of simulation\n"


def test_the_installed_experiment_names_itself():
    text = help_of(str(BIN / "nnql-experiment"))
    assert text.startswith("usage: nnql-experiment ")
    assert "nnql-experiment swarm --help" in " ".join(text.split())
    assert "experiment.py" not in text
    assert help_of(str(BIN / "nnql-experiment"), "swarm").startswith("usage: nnql-experiment swarm ")


def test_the_experiment_script_and_module_name_themselves():
    text = help_of(sys.executable, str(EXPERIMENT))
    assert text.startswith("usage: experiment.py ") and "experiment.py swarm --help" in text
    module = help_of(sys.executable, "-m", "nnql_swarm.launch.experiment")
    assert module.startswith("usage: python -m nnql_swarm.launch.experiment ")


def test_the_swarm_help_describes_the_run_not_the_module():
    text = help_of(str(BIN / "nnql-swarm"))
    assert text.startswith("usage: nnql-swarm ")
    assert "A swarm run:" in text and "launch.processes" not in text


def test_the_resume_command_carries_the_options_config_json_does_not():
    parser = build_parser()
    plain = parser.parse_args(["--agents", "4"])
    assert resume_command(plain, Path("runs/a b")).endswith(" --resume --out 'runs/a b'")
    remote = parser.parse_args(["--role", "agents", "--agent-ids", "0-2,5", "--run-id", "r",
                                "--connect", "tcp/192.0.2.1:7447", "--no-record"])
    assert resume_command(remote, Path("runs/r")).endswith(
        " --resume --out runs/r --role agents --agent-ids 0,1,2,5 "
        "--connect tcp/192.0.2.1:7447 --no-record")


def test_a_cold_kernel_cache_is_told_apart_from_a_warm_one(tmp_path):
    probe = ("from nnql_swarm.sim.runs import compiled_simulator; "
             "print(compiled_simulator())")
    # compiled, whatever this worker's environment says: a launcher run here before sets
    # NNQL_KERNEL=python in it for the processes it forks (launch.processes.process_context)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "empty-cache"),
           "NNQL_KERNEL": "compiled"}
    cold = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env,
                          timeout=120)
    assert cold.stdout.strip() == "False", cold.stderr
    plain = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True,
                           env={**env, "NNQL_KERNEL": "python"}, timeout=120)
    assert plain.stdout.strip() == "True", plain.stderr  # nothing to compile
    config = SwarmConfig(n_agents=2, width=5, height=5, episodes=1, max_steps=10)
    prepare_simulator(swarm_world(config), config)  # compiles here if this cache is cold
    assert compiled_simulator()


def test_the_kernel_cache_is_the_sources_own_even_when_numba_was_imported_first():
    """numba reads its environment at its own import: a script that imports it before the
    project must still get the cache of this version of the kernel sources, not a stale one."""
    probe = ("import numba; from nnql_swarm.protocol.jit import cache_directory; "
             "print(numba.config.CACHE_DIR == str(cache_directory()))")
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "NNQL_KERNEL")}
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env,
                          timeout=120)
    assert done.stdout.strip() == "True", done.stderr


KERNEL_SOURCE = """from nnql_swarm.protocol.jit import kernel


@kernel
def twice(x):
    return {factor} * x
"""


def test_a_second_checkout_of_the_same_kernel_sources_loads_what_the_first_compiled(tmp_path):
    """numba's cache is keyed by a source's folder name and content (``protocol.jit``), not by
    where the checkout is nor when its files were written: a fresh clone does not compile
    again what another clone of the same sources compiled; an edited source does."""
    probe = ("import sys; sys.path.insert(0, sys.argv[1]); from room import kernels; "
             "from nnql_swarm.protocol.jit import cached; before = cached(kernels.twice); "
             "kernels.twice(2); print(before, cached(kernels.twice))")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "NNQL_KERNEL": "compiled"}
    env.pop("NUMBA_CACHE_LOCATOR_CLASSES", None)  # as a fresh shell has it

    def checkout(name: str, factor: int) -> str:
        room = tmp_path / name / "room"
        room.mkdir(parents=True)
        (room / "__init__.py").write_text("")
        (room / "kernels.py").write_text(KERNEL_SOURCE.format(factor=factor))
        done = subprocess.run([sys.executable, "-c", probe, str(room.parent)], env=env,
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        return done.stdout.strip()

    assert checkout("first", 2) == "False True"  # compiled, then cached
    time.sleep(0.01)  # the second checkout's files are written later
    assert checkout("second", 2) == "True True"  # found in the cache before any call
    assert checkout("edited", 3) == "False True"  # another source: compiled anew


def test_compiling_is_announced_before_the_progress_bar(monkeypatch, capsys):
    monkeypatch.setattr(runs, "compiled_simulator", lambda: False)
    config = SwarmConfig(n_agents=2, width=5, height=5, episodes=1, max_steps=10)
    prepare_simulator(swarm_world(config), config)
    told = capsys.readouterr().err.splitlines()
    assert told[0] == COMPILING and told[1].startswith("compiled in ")


def test_every_simulator_command_compiles_before_its_progress_bar_starts(monkeypatch, tmp_path):
    from nnql_swarm.api import command
    from nnql_swarm.launch import experiment, swarm_cli

    order = []
    for module, bar in ((experiment, "progress"), (command, "progress_bar")):
        prepare, progress = module.prepare_simulator, getattr(module, bar)
        monkeypatch.setattr(module, "prepare_simulator",
                            lambda *a, prepare=prepare: (order.append("compile"), prepare(*a))[1])
        monkeypatch.setattr(module, bar, lambda *a, progress=progress, **k: (
            order.append("bar"), progress(*a, **k))[1])
    terminate = signal.getsignal(signal.SIGTERM)  # the experiment's main sets its own
    try:
        assert experiment.main(["--episodes", "2", "--seeds", "1", "--ks", "2", "--no-plots",
                                "--out", str(tmp_path / "paper")]) == 0
        assert experiment.main(["swarm", "--episodes", "5", "--seeds", "1", "--agents", "2",
                                "--grid", "5x5", "--variants", "ql", "--no-plots",
                                "--out", str(tmp_path / "swarm")]) == 0
    finally:
        signal.signal(signal.SIGTERM, terminate)
    assert swarm_cli.main(["--in-process", "--agents", "2", "--episodes", "2", "--grid", "5x5",
                           "--no-record", "--out", str(tmp_path / "run")]) == 0
    assert order == ["compile", "bar"] * 3


def test_the_command_is_a_swarm_made_from_its_options(monkeypatch, tmp_path):
    """``launch/swarm.py`` makes a Swarm of its parsed options and plays it: the same config as
    the API's Swarm of the same options, its directory prepared first."""
    from nnql_swarm.api import Swarm
    from nnql_swarm.launch import swarm_cli

    played = []
    monkeypatch.setattr(Swarm, "play", lambda self, on_row=None: played.append(self) or 0)
    out = tmp_path / "run"
    assert swarm_cli.main(["--agents", "3", "--seed", "4", "--run-id", "cmd", "--out", str(out),
                           "--in-process", "--no-progress"]) == 0
    (swarm,) = played
    assert swarm.config == Swarm(agents=3, seed=4, run_id="cmd").config
    assert swarm.out == out and (out / "config.json").is_file()



HELPED = (("nnql-swarm",), ("nnql-experiment",), ("nnql-experiment", "swarm"),
          ("nnql-experiment", "maps"), ("nnql-view",), ("nnql-faultsim",), ("nnql-router",),
          ("nnql-secure",), ("launch/maps.py",), ("launch/pogema_import.py",))


def command_line(command: tuple[str, ...]) -> list[str]:
    """An installed command, or a script of the repository's run by this interpreter."""
    if command[0].endswith(".py"):
        return [sys.executable, str(ROOT / command[0]), *command[1:]]
    return [str(BIN / command[0]), *command[1:]]


@pytest.mark.parametrize("command", HELPED, ids=" ".join)
def test_no_help_shows_a_default_in_python(command):
    """No default that is Python's (None, False, [], a tuple), none on a required option, no
    path of this machine, no markup of a docstring."""
    said = help_of(*command_line(command))
    text = " ".join(said.split())
    for python in ("(default: None)", "(default: False)", "(default: [])", "(default: (",
                   "default: True)", "``"):
        assert python not in text, f"{python} in {' '.join(command)} --help"
    assert str(ROOT) not in "".join(said.split()), f"{ROOT} in {' '.join(command)} --help"


def test_every_option_of_every_command_says_what_it_is():
    from nnql_swarm.api import command
    from nnql_swarm.launch import experiment, experiment_maps, faultsim, maps, pogema_import, view
    from nnql_swarm.launch import router, secure

    parsers = {"swarm": command.build_parser(), "experiment": experiment.build_parser(),
               "experiment swarm": experiment.build_swarm_parser(),
               "experiment maps": experiment_maps.build_maps_parser(),
               "view": view.build_parser(), "faultsim": faultsim.build_parser(),
               "router": router.build_parser(), "secure": secure.build_parser(),
               "maps.py": maps.build_parser(), "pogema_import.py": pogema_import.build_parser()}
    unexplained = [f"{name} {action.option_strings[0]}" for name, parser in parsers.items()
                   for action in parser._actions
                   if action.option_strings and not (action.help or "").strip()]
    assert not unexplained


def test_the_help_formatter_leaves_out_defaults_not_worth_reading():
    from nnql_swarm.launch.cli import DefaultsHelpFormatter, OneLineParser

    parser = OneLineParser(prog="p", formatter_class=DefaultsHelpFormatter)
    parser.add_argument("--out", required=True, help="where")
    parser.add_argument("--hosts", action="append", default=[], help="hosts")
    parser.add_argument("--fast", action="store_true", help="fast")
    parser.add_argument("--grid", default=(11, 11), help="grid")
    parser.add_argument("--k", type=int, default=7, help="k")
    parser.add_argument("--tag", default=None, help="tag")
    text = " ".join(parser.format_help().split())
    assert "--k K k (default: 7)" in text and "--grid GRID grid (default: 11,11)" in text
    assert "--out OUT where --hosts" in text and "--fast fast --grid" in text
    assert "--tag TAG tag" in text and "None" not in text


@pytest.mark.parametrize("options, message", [
    (["--goal-reward", "nan"], "the goal reward must be"),
    (["--goal-reward", "1e300"], "the goal reward must be"),
    (["--stay-reward", "inf"], "the stay reward must be"),
    (["--optimistic", "1e300"], "the optimistic initial value must be"),
    (["--max-steps", "100000000000000000"], "the messages' largest tick"),
    (["--max-steps", "1e17"], "invalid int value"),
    (["--max-steps", "10000000000"], "GiB of memory here"),
    (["--deadline", "inf"], "positive and finite"),
    (["--agent-wait", "nan"], "--agent-wait must be positive and finite"),
])
def test_what_the_wire_refuses_the_command_line_refuses_in_one_line(tmp_path, options, message):
    out = tmp_path / "run"
    done = subprocess.run([sys.executable, str(SWARM), "--out", str(out), "--no-progress",
                           *options], cwd=ROOT, capture_output=True, text=True, timeout=60)
    one_line_exit_2(done, message)
    assert not out.exists()


@pytest.mark.parametrize("text", ["[]", "null", "42", "{}"])
def test_resume_refuses_a_config_json_that_is_not_a_runs_and_appends_nothing(tmp_path, text):
    out = tmp_path / "run"
    out.mkdir()
    (out / "config.json").write_text(text + "\n")
    rows = "episode,steps\n0,12\n"
    (out / "episodes.csv").write_text(rows)
    done = subprocess.run([sys.executable, str(SWARM), "--resume", "--out", str(out),
                           "--no-progress"], cwd=ROOT, capture_output=True, text=True,
                          timeout=60)
    one_line_exit_2(done, "not a valid run config")
    assert (out / "episodes.csv").read_text() == rows


def test_a_swarm_the_machine_cannot_hold_is_refused_with_what_it_needs_and_what_there_is():
    """The memory its processes need against what is available, and the agent processes a core
    carries (``sim.capacity``; the command line reads the machine's own figures:
    ``--max-steps 10000000000`` above needs more memory than any machine has)."""
    gib = 2**30
    with pytest.raises(ValueError, match=r"512 agents of at most 100 steps need at least "
                                         r"4\.\d+ GiB of memory here \(513 processes\), and "
                                         r"this machine has 2 GiB available"):
        check_fits(513, 512, 100, available=2 * gib, cores=2)
    with pytest.raises(ValueError, match=r"1024 agent processes need at least 4 cores here \(at "
                                         r"most 256 a core\), and this machine has 2"):
        check_fits(1025, 1024, 100, available=21 * gib, cores=2)
    check_fits(513, 512, 100, available=21 * gib, cores=2)  # bench/scale.py's largest swarm
    check_fits(1, 1024, 100, own_processes=False, available=21 * gib, cores=2)  # --in-process
    assert available_bytes() is None or available_bytes() > 0


@pytest.mark.serial  # moments after the launch
@pytest.mark.full
@pytest.mark.parametrize("moment", [0.1, 0.4, 0.8, 1.2, 1.8])
def test_ctrl_c_in_the_first_seconds_stops_the_swarm_in_a_line_without_a_traceback(tmp_path,
                                                                                   moment):
    """Ctrl-C reaches every process of the terminal's group, the world and agents among them
    while they still import: the launcher stops them, and says so once."""
    from tests.swarm_helpers import group_pids, stops_within

    swarm = subprocess.Popen([sys.executable, str(SWARM), "--agents", "4", "--episodes", "50",
                              "--out", str(tmp_path / "run"), "--no-progress"],
                             cwd=ROOT, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        time.sleep(moment)
        os.killpg(swarm.pid, signal.SIGINT)
        stderr = swarm.communicate(timeout=60)[1]
        assert stops_within(swarm, 10) < 10 and not group_pids(swarm.pid)
    finally:
        if group_pids(swarm.pid):
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 130, stderr
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("interrupted"), stderr


@pytest.mark.full
def test_an_interrupted_in_process_run_says_how_to_resume_it_and_the_resumed_run_is_the_same(
        tmp_path):
    from tests.swarm_helpers import run_swarm
    from nnql_swarm.world.engine import EPISODE_FIELDS
    from nnql_swarm.world.metrics import read_episodes

    options = ("--agents", "2", "--grid", "5x5", "--max-steps", "8", "--seed", "4",
               "--episodes", "1000", "--no-record", "--in-process")
    out = tmp_path / "stopped"
    swarm = subprocess.Popen([sys.executable, str(SWARM), "--out", str(out), "--no-progress",
                              *options], cwd=ROOT, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)
    try:
        while not ((out / "episodes.csv").exists()
                   and len((out / "episodes.csv").read_text().splitlines()) > 20):
            assert swarm.poll() is None, swarm.stderr.read() if swarm.stderr else ""
            time.sleep(0.05)
        os.killpg(swarm.pid, signal.SIGINT)
        stderr = swarm.communicate(timeout=60)[1]
    finally:
        if swarm.poll() is None:
            os.killpg(swarm.pid, signal.SIGKILL)
    assert swarm.returncode == 130 and "Traceback" not in stderr, stderr
    [line] = [line for line in stderr.splitlines() if line.strip()]
    command = line.partition("continue it with ")[2]
    assert command.endswith(f"--resume --out {out} --no-record"), line
    resumed = subprocess.run([*shlex.split(command), "--no-progress"], cwd=ROOT,
                             capture_output=True, text=True, timeout=600)
    assert resumed.returncode == 0, resumed.stderr
    whole = run_swarm(tmp_path / "whole", *options)
    assert whole.returncode == 0, whole.stderr

    def rows(path):
        return [tuple(r[f] for f in EPISODE_FIELDS) for r in read_episodes(path / "episodes.csv")]

    assert rows(out) == rows(tmp_path / "whole")


@pytest.mark.full
def test_the_processes_are_forked_from_one_server_and_end_with_a_launcher_killed_outright(
        tmp_path):
    """The world and agents are forked from the server that imported the nodes once
    (``launch.processes.process_context``), not its children's launcher's; the launcher killed by
    SIGKILL alone (no handler runs) takes the server, and so every process, with it."""
    from tests.swarm_helpers import _live_processes, wait_for_rows

    out = tmp_path / "run"
    swarm = subprocess.Popen([sys.executable, str(SWARM), "--agents", "3", "--episodes", "5000",
                              "--out", str(out), "--no-progress", "--no-record",
                              "--run-id", "killed-outright"],
                             cwd=ROOT, stderr=subprocess.PIPE, text=True,
                             start_new_session=True)

    def titled() -> dict[int, str]:
        return {pid: line for pid, _, line in _live_processes()
                if line.startswith("nnql-") and line.endswith(" killed-outright")}

    try:
        wait_for_rows(out / "episodes.csv", 1, 120, swarm)
        processes = titled()
        assert len(processes) == 4, processes  # the world and 3 agents
        parents = {int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
                   for pid in processes}
        [server] = parents
        assert server != swarm.pid
        os.kill(swarm.pid, signal.SIGKILL)
        swarm.wait(timeout=10)
        deadline = time.monotonic() + 30
        while titled() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not titled()
    finally:
        if swarm.poll() is None:
            os.killpg(swarm.pid, signal.SIGKILL)
        for pid in titled():
            os.kill(pid, signal.SIGKILL)
