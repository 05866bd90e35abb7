"""The swarm across hosts: network namespaces on one private bridge stand in for three machines.

Host ``world`` runs the world (and the router), hosts ``a`` and ``b`` run agents 0-3 and 4-7, each
started by its own ``launch/swarm.py --role ...``: the very commands of docs/operations.md's "Several
machines" and "Running secured" (only the addresses and the run's size are put in). Every run is
checked like the one-machine integration test (exit 0, every episode once, no missed intent,
recordings that verify) and against the same config run ``--in-process``. The topology tests pin
down which Zenoh layouts let an agent's query reach an agent on another host.
"""

import json
import os
import shlex
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from nnql_swarm.transport.runfiles import stats_path
from nnql_swarm.transport.ports import free_port
from tests import netns
from tests.swarm_helpers import ROOT, SWARM, run_swarm
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

REASON = netns.unavailable_reason()

PY = sys.executable
ROUTER = str(ROOT / "launch" / "router.py")
PROBE = str(ROOT / "tests" / "zenoh_probe.py")
RERUN = os.path.join(os.path.dirname(sys.executable), "rerun")
README = ROOT / "docs" / "operations.md"
README_RUN = "--run-id demo --agents 8 --episodes 3 --max-steps 30 --seed 1 --no-progress"
"""What ``$RUN`` stands for in docs/operations.md's commands here: its run, made short."""
README_HOSTS = {"192.0.2.10": "world", "192.0.2.11": "a", "192.0.2.12": "b"}
RUN = ("--episodes", "3", "--max-steps", "30")
PORT = 7447
RUN_TIMEOUT_S = 150


@pytest.fixture(scope="module")
def lan():
    if REASON is not None:
        pytest.skip(f"no network namespaces: {REASON}")
    with netns.Lan(["world", "a", "b"]) as lan:
        yield lan


@pytest.fixture
def own_lan():
    """A LAN of its own, for a test that uses the documented fixed port on every host."""
    if REASON is not None:
        pytest.skip(f"no network namespaces: {REASON}")
    with netns.Lan(["world", "a", "b"]) as lan:
        yield lan


def deterministic(path: Path) -> list[tuple]:
    return [tuple(row[f] for f in EPISODE_FIELDS) for row in read_episodes(path)]


def in_process(out: Path, *options: str) -> list[tuple]:
    result = run_swarm(out, *options, "--in-process", "--no-record", timeout=120)
    assert result.returncode == 0, result.stderr
    return deterministic(out / "episodes.csv")


_STARTED: list["Launch"] = []


@pytest.fixture(autouse=True)
def stop_what_the_test_started():
    yield
    while _STARTED:
        _STARTED.pop().stop()


class Launch:
    """A process started inside a host, its output in files; stopped when its test ends."""

    def __init__(self, lan: netns.Lan, host: str, argv: list[str], logs: Path, name: str,
                 cwd: Path = ROOT) -> None:
        _STARTED.append(self)
        self.name = name
        self.stdout, self.stderr = logs / f"{name}.out", logs / f"{name}.err"
        with open(self.stdout, "w") as out, open(self.stderr, "w") as err:
            self.process = lan.popen(host, argv, cwd=cwd, stdout=out, stderr=err,
                                     env={**os.environ, "NNQL_LOG": "WARNING"})

    def wait_for_line(self, text: str, timeout: float = 30) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in self.stdout.read_text().splitlines():
                if text in line:
                    return line
            if self.process.poll() is not None:
                break
            time.sleep(0.05)
        pytest.fail(f"{self.name} never printed {text!r}: {self.stderr.read_text()[-2000:]}")

    def wait(self, timeout: float = RUN_TIMEOUT_S) -> int:
        try:
            return self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            pytest.fail(f"{self.name} did not finish in {timeout} s: "
                        f"{self.stderr.read_text()[-3000:]}")

    def errors(self) -> str:
        return self.stderr.read_text()

    def stop(self) -> None:
        """SIGTERM its process group (it is a session of its own), then SIGKILL if need be."""
        if self.process.poll() is None:
            os.killpg(self.process.pid, signal.SIGTERM)
            try:
                self.process.wait(5)
            except subprocess.TimeoutExpired:
                os.killpg(self.process.pid, signal.SIGKILL)
                self.process.wait(5)


def check_run(world_out: Path, world: Launch, agents: list[Launch], episodes: int,
              reference: list[tuple]) -> None:
    world_code = world.wait()
    codes = [a.wait(30) for a in agents]
    assert world_code == 0, world.errors()
    for launcher, code in zip(agents, codes):
        assert code == 0, launcher.errors()
    rows = read_episodes(world_out / "episodes.csv")
    assert [int(r["episode"]) for r in rows] == list(range(episodes))
    assert all(int(r["missed_intents"]) == 0 for r in rows), rows
    assert "invariants" not in world.errors()
    assert deterministic(world_out / "episodes.csv") == reference


# --- docs/operations.md's commands, as written ---

def readme_commands(block: str) -> list[tuple[str, str]]:
    """(host, command line) of docs/operations.md's code block marked ``<!-- test: block -->``."""
    text = README.read_text()
    marker = f"<!-- test: {block} -->\n```sh\n"
    assert marker in text, f"docs/operations.md lost its {block!r} commands"
    start = text.index(marker) + len(marker)
    host, commands = None, []
    for line in text[start:text.index("```", start)].splitlines():
        line = line.strip()
        if line.startswith("# on "):
            host = "local" if "any machine" in line else next(
                h for address, h in README_HOSTS.items() if address in line)
        elif line.startswith("python "):
            commands.append((host, line))
    return commands


def run_readme(block: str, lan: netns.Lan, tmp_path: Path) -> tuple[dict, Launch, list[Launch]]:
    """Run a README block: each host in a directory of its own; returns (dirs, world, agents)."""
    dirs = {h: tmp_path / h for h in ("local", "world", "a", "b")}
    for directory in dirs.values():
        directory.mkdir()
    for host in ("world", "a", "b"):  # "copy secure/ to every host": one file system here
        (dirs[host] / "secure").symlink_to(dirs["local"] / "secure", target_is_directory=True)
    world, agents = None, []
    for index, (host, line) in enumerate(readme_commands(block)):
        for address, name in README_HOSTS.items():
            line = line.replace(address, lan.ip(name))
        argv = shlex.split(line.replace("$RUN", README_RUN))
        assert argv[0] == "python" and argv[1].startswith("launch/"), line
        argv = [PY, str(ROOT / argv[1]), *argv[2:]]
        if host == "local":
            made = subprocess.run(argv, cwd=dirs["local"], capture_output=True, text=True,
                                  timeout=120)
            assert made.returncode == 0, made.stderr
            continue
        launch = Launch(lan, host, argv, tmp_path, f"{index}-{host}", cwd=dirs[host])
        if argv[1] == ROUTER:
            launch.wait_for_line("listening on")
        elif "--role" in argv and argv[argv.index("--role") + 1] == "world":
            world = launch
        else:
            agents.append(launch)
    assert world is not None and len(agents) == 2
    return dirs, world, agents


def readme_reference(tmp_path: Path) -> list[tuple]:
    return in_process(tmp_path / "in-process", *shlex.split(README_RUN))


def test_readme_router_and_clients(own_lan, tmp_path):
    """The recommended layout: a router on one host; the world and the agents its clients."""
    reference = readme_reference(tmp_path)
    dirs, world, agents = run_readme("router", own_lan, tmp_path)
    check_run(dirs["world"] / "runs" / "demo", world, agents, 3, reference)
    parts = [dirs[h] / "runs" / "demo" / "run.rrd" for h in ("world", "a", "b")]
    merged = tmp_path / "run.rrd"
    merge = subprocess.run([RERUN, "rrd", "merge", *map(str, parts), "-o", str(merged)],
                           capture_output=True, text=True, timeout=120)
    assert merge.returncode == 0, merge.stderr
    for path in parts + [merged]:
        verify = subprocess.run([RERUN, "rrd", "verify", str(path)], capture_output=True,
                                text=True, timeout=120)
        assert verify.returncode == 0, f"{path}: {verify.stderr}"


def test_readme_peer_mesh(own_lan, tmp_path):
    """No router: every agent listens on its host's address, gossip meshes them."""
    reference = readme_reference(tmp_path)
    dirs, world, agents = run_readme("mesh", own_lan, tmp_path)
    check_run(dirs["world"] / "runs" / "demo", world, agents, 3, reference)


def test_readme_running_secured(own_lan, tmp_path):
    """Mutual TLS, passwords and access control at the router, across the three hosts."""
    reference = readme_reference(tmp_path)
    dirs, world, agents = run_readme("secured", own_lan, tmp_path)
    check_run(dirs["world"] / "runs" / "demo", world, agents, 3, reference)
    stats = json.loads(stats_path(dirs["world"] / "runs" / "demo", "world").read_text())
    assert stats["rejected"] == {}


# --- several runs on one router ---

def test_two_runs_share_one_router_without_interfering(lan, tmp_path):
    """Two swarms at once through one router, told apart by their run id only."""
    seeds = {"left": "7", "right": "8"}
    references = {run_id: in_process(tmp_path / f"in-process-{run_id}", *RUN, "--agents", "4",
                                     "--seed", seed, "--run-id", run_id)
                  for run_id, seed in seeds.items()}
    assert references["left"] != references["right"]
    port = PORT + 2
    router = Launch(lan, "world", [PY, ROUTER, "--listen", f"tcp/{lan.ip('world')}:{port}"],
                    tmp_path, "router")
    router.wait_for_line("listening on")
    client = ["--mode", "client", "--connect", f"tcp/{lan.ip('world')}:{port}"]
    runs = {}
    for run_id, seed in seeds.items():
        common = [*RUN, "--agents", "4", "--seed", seed, "--run-id", run_id, "--no-progress",
                  "--no-record", *client]
        world = Launch(lan, "world", [PY, str(SWARM), *common, "--role", "world",
                                      "--out", str(tmp_path / run_id / "world")],
                       tmp_path, f"{run_id}-world")
        agents = [Launch(lan, host, [PY, str(SWARM), *common, "--role", "agents", "--agent-ids",
                                     ids, "--out", str(tmp_path / run_id / host)],
                         tmp_path, f"{run_id}-{host}")
                  for host, ids in (("a", "0-1"), ("b", "2-3"))]
        runs[run_id] = (world, agents)
    for run_id, (world, agents) in runs.items():
        check_run(tmp_path / run_id / "world", world, agents, 3, references[run_id])
    assert router.process.poll() is None, "the router died"


# Which layouts carry a query from an agent on host b to an agent on host a (the hub on host
# "world"): clients of a router, or of a peer, yes; peers only if they listen on an address the
# other host can reach (gossip then connects them directly); a router or a peer does not relay
# between two peers that are not connected to each other.
LAYOUTS = [
    ("router", "client", False, True),
    ("router", "peer", False, False),
    ("router", "peer", True, True),
    ("peer", "peer", False, False),
    ("peer", "peer", True, True),
    ("peer", "client", False, True),
]


@pytest.mark.parametrize("hub_mode, mode, listens, reachable", LAYOUTS,
                         ids=[f"{h}-hub-{m}{'-listening' if ls else ''}"
                              for h, m, ls, _ in LAYOUTS])
def test_which_layouts_reach_an_agent_on_another_host(lan, tmp_path, hub_mode, mode, listens,
                                                      reachable):
    port = 7500 + LAYOUTS.index((hub_mode, mode, listens, reachable))
    hub_endpoint = f"tcp/{lan.ip('world')}:{port}"

    def side(host: str) -> list[str]:
        options = ["--mode", mode, "--connect", hub_endpoint]
        if listens:
            options += ["--listen", f"tcp/{lan.ip(host)}:0"]
        return options

    hub = Launch(lan, "world", [PY, PROBE, "hub", "--mode", hub_mode, "--listen", hub_endpoint],
                 tmp_path, "hub")
    hub.wait_for_line("ready")
    server = Launch(lan, "a", [PY, PROBE, "serve", "--key", "probe/a", *side("a")], tmp_path,
                    "serve")
    server.wait_for_line("ready")
    asker = Launch(lan, "b", [PY, PROBE, "ask", "--key", "probe/a", "--seconds", "4", *side("b")],
                   tmp_path, "ask")
    assert asker.wait(30) == 0, asker.errors()
    result = json.loads(asker.stdout.read_text().strip().splitlines()[-1])
    assert (result["answers"] > 0) == reachable, result
    if not reachable:
        assert result["asked"] >= 3, result  # it kept asking for the whole time


# --- launch/router.py itself (no namespaces needed) ---

def test_the_router_runs_until_sigterm_and_exits_cleanly(tmp_path):
    port = free_port()
    router = subprocess.Popen([PY, ROUTER, "--listen", f"tcp/127.0.0.1:{port}"], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              start_new_session=True)
    try:
        line = router.stdout.readline()
        assert line.startswith("router ") and f"tcp/127.0.0.1:{port}" in line, router.stderr.read()
        second = subprocess.run([PY, ROUTER, "--listen", f"tcp/127.0.0.1:{port}"], cwd=ROOT,
                                capture_output=True, text=True, timeout=30)
        assert second.returncode == 1
        assert second.stderr.count("\n") == 1 and "Address already in use" in second.stderr
        assert router.poll() is None
        os.killpg(router.pid, signal.SIGTERM)
        assert router.wait(10) == 0
        assert "Traceback" not in router.stderr.read()
    finally:
        if router.poll() is None:
            os.killpg(router.pid, signal.SIGKILL)
            router.wait()


@pytest.mark.parametrize("options, message", [
    (("--listen", "nowhere"), "Endpoints must be of the form"),
    (("--listen", "tcp/127.0.0.1:99999"), "invalid port"),
    (("--connect", "tcp/127.0.0.1"), "invalid port"),
    (("--zenoh-config", "/nonexistent.json5"), "no Zenoh config file"),
    (("--port", "7447"), "unrecognized arguments"),
])
def test_bad_router_options_give_one_line(options, message):
    result = subprocess.run([PY, ROUTER, *options], cwd=ROOT, capture_output=True, text=True,
                            timeout=30)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.stderr


# --- the launcher's options for several machines (no namespaces needed) ---

@pytest.mark.parametrize("options, message", [
    (("--role", "agents", "--agent-ids", "0-1", "--connect", "tcp/127.0.0.1:7447"),
     "needs --run-id"),
    (("--zenoh-config-dir", "/nonexistent"), "no Zenoh config directory"),
    (("--zenoh-config-dir", "EMPTY"), "world.json5 (and 8 more)"),
    (("--zenoh-config-dir", "EMPTY", "--zenoh-config", "BROKEN"), "not both"),
    (("--zenoh-config", "BROKEN"), "cannot read the Zenoh config file"),
    (("--zenoh-config", "CLIENT", "--mode", "tunnel"), "invalid choice"),
])
def test_bad_several_machine_options_give_one_line(tmp_path, options, message):
    (tmp_path / "empty").mkdir()
    (tmp_path / "broken.json5").write_text("{ mode: ")
    paths = {"EMPTY": str(tmp_path / "empty"), "BROKEN": str(tmp_path / "broken.json5"),
             "CLIENT": str(ROOT / "config" / "client.json5")}
    result = run_swarm(tmp_path / "out", *(paths.get(o, o) for o in options), timeout=60)
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], result.stderr


def test_the_session_mode_is_the_option_else_the_file_else_peer():
    from nnql_swarm.transport.zenoh_files import settings

    client = ROOT / "config" / "client.json5"
    assert settings(None, [], [], client).mode == "client"
    assert settings("peer", [], [], client).mode == "peer"
    assert settings(None, [], ["tcp/192.0.2.1:7447"], None).mode == "peer"
    router = settings(None, [], [], ROOT / "config" / "router.json5")
    assert router.mode == "router" and router.zenoh_config() is not None
