"""Zenoh config files on the command line: one for every process, or one per process in a directory.

``--zenoh-config FILE`` gives every process of a launcher the same file; ``--zenoh-config-dir DIR``
gives the world ``DIR/world.json5`` and agent ``i`` ``DIR/agent-<i>.json5`` (what
``launch/secure.py`` writes: each process its own certificate and password). The session mode is
``--mode`` if given, else the file's ``mode``, else ``peer``.
"""

import json
from pathlib import Path

import zenoh

from nnql_swarm.transport.settings import MODES, TransportSettings

WORLD_FILE = "world.json5"


def agent_file_name(agent: int) -> str:
    return f"agent-{agent}.json5"


def config_files(config_dir: Path, world: bool, agents: list[int]) -> dict:
    """``{"world": path, agent: path}`` for the processes to start; ValueError if one is missing."""
    config_dir = Path(config_dir)
    if not config_dir.is_dir():
        raise ValueError(f"no Zenoh config directory at {config_dir}")
    files: dict = {}
    if world:
        files["world"] = config_dir / WORLD_FILE
    for agent in agents:
        files[agent] = config_dir / agent_file_name(agent)
    missing = [str(path) for path in files.values() if not path.is_file()]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ValueError(f"no Zenoh config file at {missing[0]}{more}")
    return files


def file_mode(path) -> str | None:
    """The ``mode`` a Zenoh config file sets (None if it sets none); ValueError if unreadable."""
    try:
        mode = json.loads(str(zenoh.Config.from_file(str(path)))).get("mode")
    except Exception as error:
        first = " ".join(str(error).split(" at /")[0].split())
        raise ValueError(f"cannot read the Zenoh config file {path}: {first}") from None
    if mode is not None and mode not in MODES:
        raise ValueError(f"{path}: mode must be one of {', '.join(MODES)}, not {mode!r}")
    return mode


def settings(mode: str | None, listen, connect, config_file) -> TransportSettings:
    """Session settings from the options: the mode falls back on the file's, then on peer."""
    if mode is None:
        mode = (file_mode(config_file) if config_file else None) or "peer"
    return TransportSettings(mode=mode, listen=tuple(listen), connect=tuple(connect),
                             config_file=str(config_file) if config_file else None)
