"""A run's options by name, to its config and to how it is played: the one path for the command
line (its parsed options) and the Python API (keyword arguments), without argv.

A run is a :class:`~nnql_swarm.protocol.config.SwarmConfig` (what is played: every value checked
there, once, with the codec's bounds) and a :class:`Launch` (how: where its processes run and
connect, what it records and shows). :func:`config_of` makes the config of options by name,
given as the command's parser leaves them or as the API's keyword arguments: a preset's learning
options first, then each option given, by its config field's name or its flag's (``agents`` or
``n_agents``), ``grid``, and ``map``, ``scen``, ``goals`` read into the map's fields.
"""

import argparse
import numbers
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from nnql_swarm.agent.agent_machine import WORLD_WAIT_S
from nnql_swarm.protocol.config import DEFAULT_PRESET, LEARNING_FIELDS, PRESETS, SwarmConfig
from nnql_swarm.recording.viewers import check_viewer_url
from nnql_swarm.launch.cli import parse_grid
from nnql_swarm.world.terrain import run_map
from nnql_swarm.world.pogema_instances import lifelong_instance
from nnql_swarm.transport.settings import MODES

RUN_NAMES = ("preset", "grid", "map", "scen", "goals")
"""Options that are no config field: the preset, and where the grid, the map and the tasks come
from (read into the config's fields)."""

FIELDS = {f.name: f for f in fields(SwarmConfig)}


def _aliases() -> dict[str, str]:
    """Each config option's flag names (``agents``, ``radius``, ``deadline``), to its field."""
    names: dict[str, str] = {}
    for f in FIELDS.values():
        flag = f.metadata.get("flag")
        for one in (flag,) if isinstance(flag, str) else flag or ():
            names[one.removeprefix("--").replace("-", "_")] = f.name
    return names


ALIASES = _aliases()


@dataclass(frozen=True)
class Launch:
    """How a run is played, beside its config (``launch/swarm.py``'s options that are not the
    run's): its directory, in this process or as processes, which of them this host starts and
    how they connect over Zenoh, what is recorded and which viewer is shown it."""

    out: Path | None = None
    resume: bool = False
    in_process: bool = False
    no_progress: bool = False
    role: str = "all"
    agent_ids: tuple[int, ...] | None = None
    world_wait: float = WORLD_WAIT_S
    agent_wait: float | None = None  # None: world.world_machine.startup_timeout
    port: int | None = None
    topology: str = "auto"
    mode: str | None = None
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    zenoh_config: str | None = None
    zenoh_config_dir: str | None = None
    no_record: bool = False
    reference: bool = False
    map_agent: int = 0
    rerun_spawn: bool = False
    rerun_connect: str | None = None
    rerun_serve_web: bool = False
    rerun_port: int = 9876
    rerun_web_port: int = 9090

    @staticmethod
    def of(args: argparse.Namespace) -> "Launch":
        """The launch options among the command's parsed ones."""
        values = {f.name: getattr(args, f.name) for f in fields(Launch)}
        for name in ("agent_ids", "listen", "connect"):
            if values[name] is not None:
                values[name] = tuple(values[name])
        return Launch(**values)


LAUNCH_DEFAULTS = Launch()

API_LAUNCH = ("world_wait", "agent_wait", "port", "topology", "mode", "listen", "connect", "zenoh_config",
              "zenoh_config_dir", "reference", "map_agent", "rerun_spawn", "rerun_connect",
              "rerun_serve_web", "rerun_port", "rerun_web_port")
"""The launch options the API takes by name; the others are :meth:`Swarm.run`'s arguments
(``out``, ``distributed``, ``record``, ``progress``), ``resume`` (the function), and the parts
of a run on several hosts (``role``, ``agent_ids``), which the command starts."""

LAUNCHER_TOPOLOGIES = ("mesh", "hub-peer", "hub-router", "star-peers")
"""The one-machine topologies the launcher starts (``transport.topology.EmbeddedLayout``; the
``router`` one needs a router process of its own)."""

LAUNCH_CHOICES = {"topology": ("auto", *LAUNCHER_TOPOLOGIES), "mode": MODES}


def split(options: Mapping[str, Any]) -> tuple[dict, dict]:
    """API options -> ``(config options, launch options)``, None left out (the default);
    raises ValueError for a name that is no option, or a value of the wrong type."""
    config: dict[str, Any] = {}
    launch: dict[str, Any] = {}
    for name, value in options.items():
        if name in API_LAUNCH:
            if value is not None:
                launch[name] = _typed(name, value, _launch_type(name))
        elif name in FIELDS or name in ALIASES or name in RUN_NAMES:
            if value is not None:
                config[name] = value
        else:
            raise ValueError(f"no option {name!r}; the options are those of launch/swarm.py "
                             f"--help, by name (agents=8 for --agents 8)")
    for name, value in launch.items():
        choices = LAUNCH_CHOICES.get(name)
        if choices and value not in choices:
            raise ValueError(f"{name} must be one of {', '.join(choices)}, not {value!r}")
    if "rerun_connect" in launch:
        try:
            check_viewer_url(launch["rerun_connect"])
        except argparse.ArgumentTypeError as error:
            raise ValueError(str(error)) from None
    return config, launch


def config_values(options: Mapping[str, Any]) -> dict:
    """The config fields that options by name give (None: not given): the preset's learning
    options, then each option given, typed as its field (an int for a float field becomes a
    float, as the command line reads it); raises ValueError for a bad name, type or grid."""
    preset = options.get("preset")
    if preset is not None and preset not in PRESETS:
        raise ValueError(f"preset must be one of {', '.join(PRESETS)}, not {preset!r}")
    values = dict(PRESETS[preset]) if preset else {}
    for name, value in options.items():
        if value is None or name in RUN_NAMES:
            continue
        field = ALIASES.get(name, name)
        if field not in FIELDS:
            raise ValueError(f"no option {name!r}; the options are those of launch/swarm.py "
                             f"--help, by name (agents=8 for --agents 8)")
        values[field] = _typed(name, value, FIELDS[field].type)
    grid = options.get("grid")
    if grid is not None:
        values["width"], values["height"] = _grid(grid)
    return values


def config_of(options: Mapping[str, Any], run_id: str | None = None) -> SwarmConfig:
    """The run's config of options by name (:func:`config_values`, the map's fields of ``map``,
    ``scen`` and ``goals``), its run id ``run_id`` or by default
    ``<preset>-<agents>a-s<seed>-<time>``; raises ValueError with the command's line for a bad
    one (every value's bounds are the config's: ``SwarmConfig``)."""
    values = config_values(options)
    run_id = run_id or values.pop("run_id", None)
    values.update(map_values(options, values))
    try:
        config = SwarmConfig(run_id="pending", **values)
        preset = options.get("preset")
        name = preset or ("custom" if set(values) & set(LEARNING_FIELDS) else DEFAULT_PRESET)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        return SwarmConfig(**{**values, "run_id": run_id or
                              f"{name}-{config.n_agents}a-s{config.seed}-{stamp}"})
    except TypeError as error:  # a map's, a scenario's or goals' rows of the wrong shape
        raise ValueError(str(error)) from None


def map_values(options: Mapping[str, Any], values: dict) -> dict:
    """The config fields of ``map``, ``scen`` and ``goals`` (none without them); raises
    ValueError, naming the file and line of a malformed map or scenario."""
    spec, scen, goals = (options.get(name) for name in ("map", "scen", "goals"))
    if spec is None:
        if scen is not None or goals is not None:
            raise ValueError(f"--{'scen' if scen is not None else 'goals'} needs --map, the map "
                             f"it is for")
        return {}
    if goals is not None and scen is not None:
        raise ValueError("--goals brings its own starts and goals: give no --scen with it")
    if "width" in values or "height" in values or values.get("obstacle_density"):
        raise ValueError("--map brings its own grid and walls: give no --grid or "
                         "--obstacle-density with it")
    d = SwarmConfig()
    agents = values.get("n_agents", d.n_agents)
    found = run_map(str(spec), None if scen is None else str(scen), values.get("seed", d.seed),
                    agents)
    if goals is not None:
        found.update(lifelong_instance(str(goals), found["map_rows"], agents))
    return found


def _grid(grid) -> tuple[int, int]:
    if isinstance(grid, str):
        try:
            return parse_grid(grid)
        except argparse.ArgumentTypeError as error:
            raise ValueError(str(error)) from None
    if isinstance(grid, (tuple, list)) and len(grid) == 2 and all(
            isinstance(side, numbers.Integral) and not isinstance(side, (bool, np.bool_))
            for side in grid):
        return int(grid[0]), int(grid[1])
    raise ValueError(f"grid is (width, height) or 'WxH', not {grid!r}")


def _launch_type(name: str):
    return {"world_wait": float, "agent_wait": float, "port": int, "map_agent": int, "rerun_port": int,
            "rerun_web_port": int, "listen": tuple, "connect": tuple, "reference": bool,
            "rerun_spawn": bool, "rerun_serve_web": bool}.get(name, str)


def _typed(name: str, value, kind):
    """``value`` as an option of type ``kind`` takes it; raises ValueError otherwise."""
    if kind is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"{name} is on or off: True or False, not {value!r}")
        return bool(value)
    if kind is int:
        if isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)):
            return int(value)
        raise ValueError(f"{name} must be an integer, not {value!r}")
    if kind is float:
        if isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_)):
            return float(value)
        raise ValueError(f"{name} must be a number, not {value!r}")
    if kind is str:
        if isinstance(value, (str, Path)):
            return str(value)
        raise ValueError(f"{name} must be a string, not {value!r}")
    if kind is tuple:
        return (str(value),) if isinstance(value, (str, Path)) else tuple(str(v) for v in value)
    return value  # the map's, the scenario's, the goals' rows: the config checks them
