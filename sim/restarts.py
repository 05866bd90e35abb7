"""Supervised restarts, on record: the run's stats keep every agent the supervisor restarted
(``<out>/stats/supervisor.json``, added to on each ``--resume``), and the launcher's last word
says that such a run is no longer the one its seed gives (a restarted agent rejoins from its last
checkpoint, having missed ticks and the episode's learning since: ``--in-process`` would differ).
"""

import json
from pathlib import Path

from nnql_swarm.transport.runfiles import stats_path, write_json_atomic

STATS_NAME = "supervisor"
"""The stats file's name (``transport.runfiles.stats_path``)."""


def record(out: Path, restarted: dict[str, list[str]], name: str = STATS_NAME) -> dict:
    """Add this launch's restarts (``{process: [how each exit that was restarted ended]}``) to
    the run's stats, and return the run's whole record ``{process: [...]}`` (empty: none ever)."""
    path = stats_path(out, name)
    try:
        before = json.loads(path.read_text()).get("restarts", {})
    except (OSError, ValueError, AttributeError):
        before = {}
    if not restarted:
        return before
    merged = {process: list(before.get(process, [])) + list(restarted.get(process, []))
              for process in sorted(set(before) | set(restarted))}
    write_json_atomic(path, {"restarts": merged})
    return merged


def of_run(out: Path, name: str = STATS_NAME) -> dict[str, list[str]]:
    """The run's record of restarts (:func:`record`), empty where none was ever made."""
    return record(out, {}, name)


def finished(out: Path) -> str:
    """The launcher's last line on a run that finished: where it is, and whether it is still
    the run its seed gives."""
    if not of_run(out):
        return f"run finished: {out}"
    return (f"run finished: {out}; not the run its seed gives (the supervisor restarted agents: "
            f"{stats_path(out, STATS_NAME)})")


def warning(record: dict[str, list[str]]) -> str | None:
    """The launcher's line on a run with restarts (None without)."""
    if not record:
        return None
    told = ", ".join(f"{process} {len(exits)} time{'s' if len(exits) > 1 else ''} "
                     f"({exits[-1]})" for process, exits in record.items())
    return (f"warning: the supervisor restarted {told}: the run is no longer the run its seed "
            f"gives (a restarted agent rejoins from its last checkpoint; --in-process would "
            f"differ); see {STATS_NAME}.json in the run's stats")
