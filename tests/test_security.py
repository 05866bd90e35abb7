"""The secured swarm: mutual TLS, user/password and access control at the router (launch/secure.py).

Each test module run generates its own CA, certificates and passwords. A router on loopback runs
the generated config; sessions opened here play the world, honest agents and a misbehaving agent.
Checked: nobody without credentials gets in; an authenticated agent cannot publish another
agent's intent, answer for it, eavesdrop on its observations, or speak for the world (the router
drops it: the target never receives it, while the same session's legitimate messages arrive); and
a whole run (world + 8 agents, all clients of the secured router) completes like an unsecured one.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import zenoh

from nnql_swarm.launch import secure
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.messages import (
    CONTROL_SHUTDOWN, WORLD_SENDER, Control, Intent, Observation, agent_sender, encode,
)
from nnql_swarm.transport.runfiles import stats_path
from nnql_swarm.transport.ports import free_port
from tests.swarm_helpers import ROOT, run_swarm
from nnql_swarm.world.engine import EPISODE_FIELDS
from nnql_swarm.world.metrics import read_episodes

pytestmark = pytest.mark.full  # real process trees: the whole suite's (make test-all)

RUN_ID = "sec"
AGENTS = 8
ROUTER = ROOT / "launch" / "router.py"
VARIANTS = {
    "mtls+password": dict(tls=True, password=True),
    "mtls": dict(tls=True, password=False),
    "password": dict(tls=False, password=True),
}


class Secured:
    """A generated credentials directory and a router running its config."""

    def __init__(self, directory: Path, port: int, tls: bool, password: bool) -> None:
        self.dir, self.port, self.tls, self.password = directory, port, tls, password
        self.router: subprocess.Popen | None = None

    def start(self) -> None:
        self.log = open(self.dir.parent / f"router-{self.port}.log", "w+")
        self.router = subprocess.Popen(
            [sys.executable, str(ROUTER), "--zenoh-config", str(self.dir / "router.json5")],
            cwd=ROOT, stdout=subprocess.PIPE, stderr=self.log, text=True, start_new_session=True)
        line = self.router.stdout.readline()
        assert "listening on" in line, self.log.read()

    def stop(self) -> None:
        if self.router is not None and self.router.poll() is None:
            os.killpg(self.router.pid, signal.SIGTERM)
            assert self.router.wait(10) == 0
        self.log.close()

    def config(self, name: str, **overrides) -> zenoh.Config:
        config = zenoh.Config.from_file(str(self.dir / f"{name}.json5"))
        config.insert_json5("scouting/timeout", "1500")
        for key, value in overrides.items():
            config.insert_json5(key, json.dumps(value))
        return config

    def open(self, name: str, **overrides) -> zenoh.Session:
        return zenoh.open(self.config(name, **overrides))

    def password_of(self, name: str) -> str:
        return json.loads(self._strip_comments(self.dir / f"{name}.json5"))["transport"]["auth"][
            "usrpwd"]["password"]

    @staticmethod
    def _strip_comments(path: Path) -> str:
        lines = path.read_text().splitlines()
        return "\n".join(line for line in lines if not line.startswith("//"))


def make_secured(base: Path, variant: str) -> Secured:
    port = free_port()
    options = VARIANTS[variant]
    directory = base / variant
    secure.generate(directory, AGENTS, ["127.0.0.1", "localhost"], port=port, **options)
    secured = Secured(directory, port, **options)
    secured.start()
    return secured


@pytest.fixture(scope="module")
def routers(tmp_path_factory):
    """One running router per variant, made on first use and shared by the module's tests."""
    made: dict[str, Secured] = {}

    def get(variant: str) -> Secured:
        if variant not in made:
            made[variant] = make_secured(tmp_path_factory.mktemp("secure"), variant)
        return made[variant]

    yield get
    for router in made.values():
        router.stop()


@pytest.fixture(scope="module", params=list(VARIANTS))
def secured(request, routers):
    return routers(request.param)


@pytest.fixture(scope="module", params=[v for v, o in VARIANTS.items() if o["password"]])
def with_password(request, routers):
    return routers(request.param)


@pytest.fixture(scope="module", params=[v for v, o in VARIANTS.items() if o["tls"]])
def with_certificates(request, routers):
    return routers(request.param)


@pytest.fixture(scope="module")
def full(routers):
    return routers("mtls+password")


class Inbox:
    """What one subscriber received: (key, payload) pairs."""

    def __init__(self) -> None:
        self.items: list[tuple[str, bytes]] = []

    def __call__(self, sample: zenoh.Sample) -> None:
        self.items.append((str(sample.key_expr), sample.payload.to_bytes()))

    def wait_for(self, payload: bytes, timeout: float = 10) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if any(p == payload for _, p in self.items):
                time.sleep(0.3)  # anything sent before it had time to arrive too
                return
            time.sleep(0.02)
        pytest.fail(f"{payload!r} never arrived; got {self.items}")

    def payloads(self) -> list[bytes]:
        return [p for _, p in self.items]


def intent(agent: int, action: int = 1, tick: int = 1) -> bytes:
    return encode(Intent(run=RUN_ID, tick=tick, sender=agent_sender(agent), agent=agent,
                         episode=0, action=action))


def observation(agent: int, tick: int = 1) -> bytes:
    return encode(Observation(run=RUN_ID, tick=tick, sender=WORLD_SENDER, agent=agent, episode=0,
                              step=0, position=(1, 1), goal=(2, 2), neighbours=b"", rank=0,
                              reward_ds=0.0, reward_ca=0.0, collided=False, arrived=False,
                              episode_end=False))


def answers(session: zenoh.Session, agent: int) -> list[bytes]:
    key = f"{keys.intent_key(RUN_ID, agent)}?{keys.intent_query_params(1)}"
    return [r.ok.payload.to_bytes() for r in session.get(key, timeout=2.0) if r.ok]


# --- nobody without credentials gets in ---

def test_the_right_credentials_open_a_session(secured):
    with secured.open("agent-0") as session:
        deadline = time.monotonic() + 5
        while not list(session.info.routers_zid()) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert list(session.info.routers_zid()), "connected to no router"


def test_a_session_without_credentials_cannot_join(secured):
    plain = {"transport/link/tls": {}, "transport/auth/usrpwd": {}}
    with pytest.raises(zenoh.ZError):
        secured.open("agent-0", **plain, **{"connect/endpoints": [f"tcp/127.0.0.1:{secured.port}"]})
    if secured.tls:
        with pytest.raises(zenoh.ZError):  # TLS that trusts the CA, but no client certificate
            secured.open("agent-0", **{"transport/link/tls/connect_certificate": None,
                                       "transport/link/tls/connect_private_key": None,
                                       "transport/link/tls/enable_mtls": False})


def test_a_wrong_password_cannot_join(with_password):
    with pytest.raises(zenoh.ZError):
        with_password.open("agent-0", **{"transport/auth/usrpwd/password": "not-the-password"})
    with pytest.raises(zenoh.ZError):
        with_password.open("agent-0", **{"transport/auth/usrpwd": {}})


def test_a_certificate_from_another_ca_cannot_join(with_certificates, tmp_path):
    secure.make_ca(tmp_path)
    secure.make_certificate(tmp_path, "agent-0", ["agent-0"], server=False)
    with pytest.raises(zenoh.ZError):
        with_certificates.open("agent-0", **{
            "transport/link/tls/connect_certificate": str(tmp_path / "agent-0.pem"),
            "transport/link/tls/connect_private_key": str(tmp_path / "agent-0.key")})


def test_mixed_identities_get_nothing_through(full):
    """Agent 0's certificate with agent 1's password: in, but no subject matches, so all denied."""
    world_inbox = Inbox()
    as_agent1 = {"transport/auth/usrpwd/user": "agent-1",
                 "transport/auth/usrpwd/password": full.password_of("agent-1")}
    with full.open("world") as world, full.open("agent-1") as honest, \
            full.open("agent-0", **as_agent1) as mixed:
        world.declare_subscriber(keys.intent_key_all(RUN_ID), world_inbox)
        time.sleep(0.5)
        mixed.put(keys.intent_key(RUN_ID, 0), intent(0))
        mixed.put(keys.intent_key(RUN_ID, 1), intent(1))
        honest.put(keys.intent_key(RUN_ID, 1), intent(1, action=2))
        world_inbox.wait_for(intent(1, action=2))
        assert world_inbox.payloads() == [intent(1, action=2)]


# --- an authenticated agent says only what its role says ---

def test_an_agent_cannot_publish_another_agents_intent(secured):
    world_inbox = Inbox()
    with secured.open("world") as world, secured.open("agent-1") as agent1:
        world.declare_subscriber(keys.intent_key_all(RUN_ID), world_inbox)
        time.sleep(0.5)
        agent1.put(keys.intent_key(RUN_ID, 0), intent(0))  # well formed: only the key gives it away
        agent1.put(keys.intent_key(RUN_ID, 2), intent(2))
        agent1.put(keys.intent_key(RUN_ID, 1), intent(1))  # its own, sent last on the same link
        world_inbox.wait_for(intent(1))
        assert world_inbox.items == [(keys.intent_key(RUN_ID, 1), intent(1))]


def test_an_agent_cannot_speak_for_the_world(secured):
    inbox = Inbox()
    shutdown = encode(Control(run=RUN_ID, tick=1, sender=WORLD_SENDER, command=CONTROL_SHUTDOWN))
    with secured.open("world") as world, secured.open("agent-0") as agent0, \
            secured.open("agent-1") as agent1:
        agent0.declare_subscriber(keys.obs_key(RUN_ID, 0), inbox)
        agent0.declare_subscriber(keys.control_key(RUN_ID), inbox)
        time.sleep(0.5)
        agent1.put(keys.obs_key(RUN_ID, 0), observation(0, tick=7))
        agent1.put(keys.control_key(RUN_ID), shutdown)
        world.put(keys.obs_key(RUN_ID, 0), observation(0))
        inbox.wait_for(observation(0))
        assert inbox.payloads() == [observation(0)]
        world.put(keys.control_key(RUN_ID), shutdown)
        inbox.wait_for(shutdown)


def test_an_agent_cannot_eavesdrop_on_another_agents_observations(secured):
    mine, theirs = Inbox(), Inbox()
    with secured.open("world") as world, secured.open("agent-0") as agent0, \
            secured.open("agent-1") as agent1:
        agent0.declare_subscriber(keys.obs_key(RUN_ID, 0), theirs)
        agent1.declare_subscriber(keys.obs_key(RUN_ID, 0), mine)
        agent1.declare_subscriber(keys.obs_key(RUN_ID, 1), mine)
        time.sleep(0.5)
        world.put(keys.obs_key(RUN_ID, 0), observation(0))
        world.put(keys.obs_key(RUN_ID, 1), observation(1))
        mine.wait_for(observation(1))
        theirs.wait_for(observation(0))
        assert mine.payloads() == [observation(1)]


def test_an_agent_cannot_answer_for_another_agent(secured):
    with secured.open("agent-0") as agent0, secured.open("agent-1") as agent1, \
            secured.open("agent-2") as agent2:
        agent1.declare_queryable(keys.intent_key(RUN_ID, 0),
                                 lambda q: q.reply(q.key_expr, intent(0, action=4)))
        agent1.declare_queryable(keys.intent_key(RUN_ID, 1),
                                 lambda q: q.reply(q.key_expr, intent(1, action=3)))
        time.sleep(0.5)
        assert answers(agent2, 1) == [intent(1, action=3)]  # a neighbour's own answer arrives
        assert answers(agent2, 0) == []  # the forged queryable is never reached
        agent0.declare_queryable(keys.intent_key(RUN_ID, 0),
                                 lambda q: q.reply(q.key_expr, intent(0, action=2)))
        time.sleep(0.5)
        assert answers(agent2, 0) == [intent(0, action=2)]


def test_an_agent_cannot_pretend_to_be_alive_as_another(secured):
    with secured.open("world") as world, secured.open("agent-1") as agent1:
        tokens = [agent1.liveliness().declare_token(key) for key in (  # noqa: F841 (kept alive)
            keys.alive_key(RUN_ID, keys.ROLE_AGENT, 0), keys.alive_key(RUN_ID, keys.ROLE_AGENT, 1),
            keys.alive_key(RUN_ID, keys.ROLE_WORLD, 0))]
        time.sleep(0.5)
        seen = {str(r.ok.key_expr) for role in (keys.ROLE_AGENT, keys.ROLE_WORLD)
                for r in world.liveliness().get(keys.alive_key_all(RUN_ID, role), timeout=2.0)
                if r.ok}
        assert seen == {keys.alive_key(RUN_ID, keys.ROLE_AGENT, 1)}


# --- the run itself ---

def test_a_secured_run_completes_like_an_unsecured_one(full, tmp_path):
    options = ("--agents", str(AGENTS), "--episodes", "3", "--max-steps", "30", "--seed", "4",
               "--run-id", "secured", "--no-record")
    local = run_swarm(tmp_path / "local", *options, "--in-process", timeout=120)
    assert local.returncode == 0, local.stderr
    result = run_swarm(tmp_path / "run", *options, "--zenoh-config-dir", str(full.dir), timeout=150)
    assert result.returncode == 0, result.stderr
    rows = read_episodes(tmp_path / "run" / "episodes.csv")
    assert [int(r["episode"]) for r in rows] == [0, 1, 2]
    assert all(int(r["missed_intents"]) == 0 for r in rows)

    def deterministic(path: Path) -> list[tuple]:
        return [tuple(row[f] for f in EPISODE_FIELDS) for row in read_episodes(path)]

    assert deterministic(tmp_path / "run" / "episodes.csv") == deterministic(
        tmp_path / "local" / "episodes.csv")
    stats = json.loads(stats_path(tmp_path / "run", "world").read_text())
    assert stats["completed"] and stats["rejected"] == {}


# --- the example configs shipped under config/secure ---

EXAMPLE_DIR = ROOT / "config" / "secure"
EXAMPLE_PASSWORD = "see-passwords.txt-written-by-launch/secure.py"


def example_configs(tmp: Path) -> dict[str, str]:
    """What ``config/secure`` holds: secure.py's configs for 2 agents, passwords masked."""
    secure.generate(tmp, 2, ["192.0.2.1"], install_dir=Path("/etc/nnql/secure"))
    texts = {}
    for path in sorted(tmp.glob("*.json5")):
        text = path.read_text()
        if path.name != "router.json5":
            config = json.loads(Secured._strip_comments(path))
            password = config["transport"]["auth"]["usrpwd"]["password"]
            text = text.replace(password, EXAMPLE_PASSWORD)
        texts[path.name] = text
    return texts


def test_the_shipped_example_configs_are_what_secure_py_writes(tmp_path):
    expected = example_configs(tmp_path)
    shipped = {path.name: path.read_text() for path in sorted(EXAMPLE_DIR.glob("*.json5"))}
    assert shipped == expected, "regenerate: python -c 'from tests.test_security import " \
                                "write_examples; write_examples()'"
    for name in shipped:
        zenoh.Config.from_file(str(EXAMPLE_DIR / name))  # Zenoh reads every one of them


def write_examples() -> None:
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        EXAMPLE_DIR.mkdir(parents=True, exist_ok=True)
        for name, text in example_configs(Path(tmp) / "secure").items():
            (EXAMPLE_DIR / name).write_text(text)


def test_secure_py_refuses_to_overwrite_and_gives_one_line(tmp_path):
    command = [sys.executable, str(ROOT / "launch" / "secure.py"), "--out", str(tmp_path / "s"),
               "--agents", "2", "--router-host", "127.0.0.1"]
    first = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert first.returncode == 0, first.stderr
    before = (tmp_path / "s" / "ca.pem").read_bytes()
    again = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert again.returncode == 2 and "already exists" in again.stderr
    assert len(again.stderr.strip().splitlines()) == 1
    assert (tmp_path / "s" / "ca.pem").read_bytes() == before
    for name in ("ca.key", "agent-0.key", "passwords.txt", "agent-0.json5"):
        assert (tmp_path / "s" / name).stat().st_mode & 0o077 == 0, f"{name} is readable by others"


def test_run_id_restricted_credentials_work_for_that_run_only(tmp_path):
    port = free_port()
    secure.generate(tmp_path / "s", 2, ["127.0.0.1"], port=port, run_id="only")
    secured = Secured(tmp_path / "s", port, tls=True, password=True)
    secured.start()
    try:
        inbox = Inbox()
        with secured.open("world") as world, secured.open("agent-0") as agent0:
            world.declare_subscriber(keys.intent_key_all("other"), inbox)
            world.declare_subscriber(keys.intent_key_all("only"), inbox)
            time.sleep(0.5)
            agent0.put(keys.intent_key("other", 0), b"other run")
            agent0.put(keys.intent_key("only", 0), b"this run")
            inbox.wait_for(b"this run")
            assert inbox.payloads() == [b"this run"]
    finally:
        secured.stop()
