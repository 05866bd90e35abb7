#!/usr/bin/env python3
"""Generate what a secured swarm needs: certificates, passwords and one Zenoh config per process.

    python launch/secure.py --out secure --agents 8 --router-host 192.0.2.1

writes into ``secure/``:

- ``ca.pem`` (every process trusts it) and ``ca.key`` (keep it off the hosts: it signs certificates)
- ``router.pem/.key`` (its names: every ``--router-host``), ``world.pem/.key`` and
  ``agent-<i>.pem/.key`` (client certificates whose common name is the process's name: mutual TLS)
- ``passwords.txt``: the router's user/password dictionary (one ``user:password`` line each)
- ``router.json5``: a router listening on ``tls/0.0.0.0:<port>`` that accepts only clients with a
  certificate from this CA *and* a password from the dictionary, and whose access control lets
  each process say only what its role says (default deny):
  the world publishes observations and control and subscribes to intents; agent ``i`` publishes
  and answers queries only on its own intent key, subscribes only to its own observations and the
  control key, and may query any agent's intent; everyone keeps liveliness on its own token.
- ``world.json5`` and ``agent-<i>.json5``: clients of that router with their own certificate and
  password (``launch/swarm.py --zenoh-config-dir secure`` picks the right file per process).

``--no-tls`` (user/password over TCP, access control by user name) and ``--no-password`` (mutual
TLS only, access control by certificate name) generate the weaker variants. ``--install-dir``
names where the directory will be on the hosts, when that is not where it is generated (the
configs name certificate files by absolute path). Certificates are made with the ``openssl``
command. Existing files are never overwritten unless ``--force``.
"""

import argparse
import ipaddress
import json
import os
import secrets
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

from nnql_swarm.launch.cli import DefaultsHelpFormatter, OneLineParser
from nnql_swarm.protocol import keys
from nnql_swarm.protocol.messages import MAX_AGENTS

DEFAULT_PORT = 7447
WORLD = "world"
CERT_DAYS = 825
EXIT_FAILED = 1


class SecureError(Exception):
    """Generating failed (openssl missing or failing): one line on stderr, exit code 1."""


class UsageError(SecureError):
    """A bad option, or files in the way: one line on stderr, exit code 2."""


def agent_name(agent: int) -> str:
    return f"agent-{keys.validate_agent(agent)}"


# --- key expressions of the access-control rules (built from protocol.keys, never spelled here) ---

def _run_pattern(key: str, run_id: str | None) -> str:
    """``key`` (built for a placeholder run) with its run chunk set to ``run_id`` or ``*``."""
    parts = key.split("/")
    parts[1] = run_id or "*"
    return "/".join(parts)


def _last_chunk_any(key: str) -> str:
    return key.rsplit("/", 1)[0] + "/*"


class KeySpace:
    """The key expressions the rules name, for one run id or (``None``) every run."""

    def __init__(self, run_id: str | None) -> None:
        if run_id is not None:
            keys.validate_run_id(run_id)
        self.run_id = run_id
        self._placeholder = "x"

    def _k(self, key: str) -> str:
        return _run_pattern(key, self.run_id)

    def intent(self, agent: int) -> str:
        return self._k(keys.intent_key(self._placeholder, agent))

    def intent_all(self) -> str:
        return self._k(keys.intent_key_all(self._placeholder))

    def obs(self, agent: int) -> str:
        return self._k(keys.obs_key(self._placeholder, agent))

    def obs_all(self) -> str:
        return _last_chunk_any(self.obs(0))

    def control(self) -> str:
        return self._k(keys.control_key(self._placeholder))

    def alive(self, role: str, ident) -> str:
        return self._k(keys.alive_key(self._placeholder, role, ident))

    def alive_all(self, role: str) -> str:
        return self._k(keys.alive_key_all(self._placeholder, role))


def _rule(rule_id: str, flow: str, messages: list[str], key_exprs: list[str]) -> dict:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages,
            "key_exprs": key_exprs}


def access_control(n_agents: int, run_id: str | None, by_cert: bool, by_user: bool) -> dict:
    """The router's ``access_control`` section: default deny, one allow-list per process.

    ``ingress`` is what a process may send into the router, ``egress`` what the router may hand
    it. Rules on declarations name the whole key expression declared (a rule on ``agent/3/intent``
    does not match a declaration of ``agent/*/intent``), hence the wildcards in egress rules.
    """
    ks = KeySpace(run_id)
    liveliness_all = [ks.alive_all(keys.ROLE_AGENT), ks.alive_all(keys.ROLE_WORLD)]
    world_in = [
        _rule("world-in-publish", "ingress", ["put"], [ks.obs_all(), ks.control()]),
        _rule("world-in-subscribe", "ingress", ["declare_subscriber"], [ks.intent_all()]),
        _rule("world-in-token", "ingress", ["liveliness_token"], [ks.alive(keys.ROLE_WORLD, 0)]),
        _rule("world-in-liveliness", "ingress",
              ["declare_liveliness_subscriber", "liveliness_query"], liveliness_all),
    ]
    world_out = [
        _rule("world-out-intents", "egress", ["put"], [ks.intent_all()]),
        _rule("world-out-declarations", "egress", ["declare_subscriber"],
              [ks.obs_all(), ks.control()]),
        _rule("world-out-tokens", "egress", ["liveliness_token"], liveliness_all),
    ]
    rules = world_in + world_out
    subjects = [_subject(WORLD, by_cert, by_user)]
    policies = [{"id": "world", "subjects": [WORLD], "rules": [r["id"] for r in rules]}]
    for agent in range(n_agents):
        name = agent_name(agent)
        own = ks.intent(agent)
        mine = [
            _rule(f"{name}-in-own-intent", "ingress", ["put", "declare_queryable", "reply"], [own]),
            _rule(f"{name}-in-ask", "ingress", ["query"], [ks.intent_all()]),
            _rule(f"{name}-in-subscribe", "ingress", ["declare_subscriber"],
                  [ks.obs(agent), ks.control()]),
            _rule(f"{name}-in-token", "ingress", ["liveliness_token"],
                  [ks.alive(keys.ROLE_AGENT, agent)]),
            _rule(f"{name}-in-liveliness", "ingress",
                  ["declare_liveliness_subscriber", "liveliness_query"], liveliness_all),
            _rule(f"{name}-out-world", "egress", ["put"], [ks.obs(agent), ks.control()]),
            _rule(f"{name}-out-asked", "egress", ["query"], [own]),
            _rule(f"{name}-out-answers", "egress", ["reply"], [ks.intent_all()]),
            _rule(f"{name}-out-declarations", "egress", ["declare_subscriber", "declare_queryable"],
                  [ks.intent_all(), own]),
            _rule(f"{name}-out-tokens", "egress", ["liveliness_token"], liveliness_all),
        ]
        rules += mine
        subjects.append(_subject(name, by_cert, by_user))
        policies.append({"id": name, "subjects": [name], "rules": [r["id"] for r in mine]})
    return {"enabled": True, "default_permission": "deny", "rules": rules, "subjects": subjects,
            "policies": policies}


def _subject(name: str, by_cert: bool, by_user: bool) -> dict:
    subject: dict[str, str | list[str]] = {"id": name}
    if by_cert:
        subject["cert_common_names"] = [name]
    if by_user:
        subject["usernames"] = [name]
    return subject


# --- certificates (the openssl command) ---

def _openssl(*args: str, cwd: Path) -> None:
    result = subprocess.run(["openssl", *args], cwd=cwd, capture_output=True, text=True)
    if result.returncode != 0:
        last = (result.stderr.strip().splitlines() or ["failed"])[-1]
        raise SecureError(f"openssl {args[0]}: {last}")


def _subject_alt_names(hosts: list[str]) -> str:
    names = []
    for host in hosts:
        try:
            ipaddress.ip_address(host)
            names.append(f"IP:{host}")
        except ValueError:
            names.append(f"DNS:{host}")
    return ",".join(names)


def make_ca(out: Path) -> None:
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
             "-keyout", "ca.key", "-out", "ca.pem", "-days", str(CERT_DAYS),
             "-subj", "/CN=nnql swarm CA",
             "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign", cwd=out)


def make_certificate(out: Path, name: str, alt_names: list[str], server: bool) -> None:
    """``<name>.pem`` and ``<name>.key`` signed by the CA in ``out``; CN = ``name``."""
    usage = "serverAuth,clientAuth" if server else "clientAuth"
    with tempfile.TemporaryDirectory() as tmp:
        extensions = Path(tmp) / "ext.cnf"
        extensions.write_text(
            "basicConstraints=critical,CA:FALSE\n"
            "keyUsage=critical,digitalSignature\n"
            f"extendedKeyUsage={usage}\n"
            f"subjectAltName={_subject_alt_names(alt_names)}\n")
        csr = Path(tmp) / "req.csr"
        _openssl("req", "-new", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:P-256", "-nodes",
                 "-keyout", f"{name}.key", "-out", str(csr), "-subj", f"/CN={name}", cwd=out)
        _openssl("x509", "-req", "-in", str(csr), "-CA", "ca.pem", "-CAkey", "ca.key",
                 "-set_serial", str(secrets.randbits(63)), "-days", str(CERT_DAYS),
                 "-extfile", str(extensions), "-out", f"{name}.pem", cwd=out)
    os.chmod(out / f"{name}.key", 0o600)


# --- Zenoh configs ---

def _json5(comment: str, config: dict) -> str:
    lines = [f"// {line}" if line else "//" for line in comment.strip().splitlines()]
    return "\n".join(lines) + "\n" + json.dumps(config, indent=2) + "\n"


def router_config(install: Path, port: int, n_agents: int, run_id: str | None,
                  tls: bool, password: bool) -> dict:
    proto = "tls" if tls else "tcp"
    config: dict = {
        "mode": "router",
        "listen": {"endpoints": [f"{proto}/0.0.0.0:{port}"]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {"protocols": [proto]}},
        "access_control": access_control(n_agents, run_id, by_cert=tls, by_user=password),
    }
    if tls:
        config["transport"]["link"]["tls"] = {
            "root_ca_certificate": str(install / "ca.pem"),
            "listen_certificate": str(install / "router.pem"),
            "listen_private_key": str(install / "router.key"),
            "enable_mtls": True,
        }
    if password:
        dictionary = str(install / "passwords.txt")
        config["transport"]["auth"] = {"usrpwd": {"dictionary_file": dictionary}}
    return config


def client_config(install: Path, name: str, router: str, tls: bool,
                  password: str | None) -> dict:
    config: dict = {
        "mode": "client",
        "connect": {"endpoints": [router]},
        "listen": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}, "gossip": {"enabled": False}},
        "transport": {"link": {}},
    }
    if tls:
        config["transport"]["link"]["tls"] = {
            "root_ca_certificate": str(install / "ca.pem"),
            "connect_certificate": str(install / f"{name}.pem"),
            "connect_private_key": str(install / f"{name}.key"),
            "enable_mtls": True,
        }
    if password is not None:
        config["transport"]["auth"] = {"usrpwd": {"user": name, "password": password}}
    return config


def generate(out: Path, n_agents: int, router_hosts: list[str], port: int = DEFAULT_PORT,
             install_dir: Path | None = None, run_id: str | None = None, tls: bool = True,
             password: bool = True, force: bool = False) -> list[Path]:
    """Write everything into ``out``; returns the files written. Raises SecureError."""
    if not tls and not password:
        raise UsageError("--no-tls and --no-password together would leave nothing to check")
    if not 1 <= n_agents <= MAX_AGENTS:
        raise UsageError(f"agents must be 1..{MAX_AGENTS}")
    if not 1 <= port <= 65535:
        raise UsageError(f"the port must be 1..65535, not {port}")
    if not router_hosts:
        raise UsageError("give the router's address with --router-host (repeatable)")
    if run_id is not None:
        try:
            keys.validate_run_id(run_id)
        except ValueError as error:
            raise UsageError(str(error)) from None
    if tls and shutil.which("openssl") is None:
        raise SecureError("the openssl command is needed to make certificates (or use --no-tls)")
    out = Path(out)
    install = Path(install_dir) if install_dir is not None else out.resolve()
    if not install.is_absolute():
        raise UsageError(f"--install-dir must be an absolute path, not {install}")
    names = [WORLD] + [agent_name(i) for i in range(n_agents)]
    planned = [out / "router.json5", out / "passwords.txt"] + [out / f"{n}.json5" for n in names]
    if tls:
        planned += [out / f"{n}.{ext}" for n in ["ca", "router", *names] for ext in ("pem", "key")]
    in_the_way = [p for p in planned if p.exists()]
    if in_the_way and not force:
        raise UsageError(f"{in_the_way[0]} already exists "
                         "(use --force to replace, or another --out)")
    out.mkdir(parents=True, exist_ok=True)
    router = f"{'tls' if tls else 'tcp'}/{router_hosts[0]}:{port}"
    written: list[Path] = []
    if tls:
        make_ca(out)
        os.chmod(out / "ca.key", 0o600)
        make_certificate(out, "router", router_hosts, server=True)
        for name in names:
            make_certificate(out, name, [name], server=False)
        written += [out / f"{n}.{ext}" for n in ["ca", "router", *names] for ext in ("pem", "key")]
    passwords = {name: secrets.token_urlsafe(18) for name in names} if password else {}
    if password:
        dictionary = out / "passwords.txt"
        dictionary.write_text("".join(f"{n}:{p}\n" for n, p in passwords.items()))
        os.chmod(dictionary, 0o600)
        written.append(dictionary)
    scope = f"run {run_id}" if run_id else "any run id"
    checks = " + ".join(c for c, on in (("mutual TLS", tls), ("user/password", password)) if on)
    router_file = out / "router.json5"
    router_file.write_text(_json5(
        f"nnQL swarm router ({checks}, access control for {n_agents} agents, {scope}).\n"
        "Generated by launch/secure.py. Run: python launch/router.py --zenoh-config "
        f"{install / 'router.json5'}",
        router_config(install, port, n_agents, run_id, tls, password)))
    written.append(router_file)
    for name in names:
        path = out / f"{name}.json5"
        path.write_text(_json5(
            f"nnQL swarm: {name} as a client of the secured router {router}.\n"
            "Generated by launch/secure.py; holds a password: keep it private.",
            client_config(install, name, router, tls, passwords.get(name))))
        os.chmod(path, 0o600)
        written.append(path)
    return written


def build_parser() -> OneLineParser:
    p = OneLineParser(description=__doc__.split("\n\n")[0],
                      formatter_class=DefaultsHelpFormatter)
    p.add_argument("--out", type=Path, required=True, help="directory to write into")
    p.add_argument("--agents", type=int, required=True, help="number of agents")
    p.add_argument("--router-host", action="append", default=[], metavar="HOST",
                   help="the router's address or DNS name as clients reach it (repeatable; "
                        "the first is the one clients connect to)")
    p.add_argument("--port", type=int, default=DEFAULT_PORT, help="the router's port")
    p.add_argument("--install-dir", type=Path, default=None,
                   help="absolute path of the directory on the hosts (default: --out)")
    p.add_argument("--run-id", default=None,
                   help="allow this run id only (default: any run id)")
    p.add_argument("--no-tls", action="store_true",
                   help="plain TCP with user/password only (traffic is not encrypted)")
    p.add_argument("--no-password", action="store_true", help="mutual TLS only")
    p.add_argument("--force", action="store_true", help="replace existing files")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        written = generate(args.out, args.agents, args.router_host, args.port, args.install_dir,
                           args.run_id, tls=not args.no_tls, password=not args.no_password,
                           force=args.force)
    except UsageError as error:
        parser.error(str(error))
    except SecureError as error:
        print(f"secure.py: error: {error}", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {len(written)} files to {args.out}: router.json5, world.json5, "
          f"agent-0..{args.agents - 1}.json5 and their credentials")
    return 0


if __name__ == "__main__":
    sys.exit(main())
