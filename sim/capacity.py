"""Whether this machine can hold the part of a run it is asked to start: the memory its
processes need, roughly, against what the machine has available (``/proc/meminfo``).

A run that does not fit would otherwise start and fail slowly: processes killed for memory and
restarted for ever, or a machine swapping to a crawl. The estimate is a floor (``bench/scale.py``
measures 55 to 64 MiB an agent process, ``docs/performance.md``), so a refused run would not
have fitted.
"""

from pathlib import Path

from nnql_swarm.protocol.actions import N_ACTIONS

MIB = 2**20
PROCESS_MIB = 50
"""An agent or world process before its run's arrays: the interpreter, Zenoh, numpy."""
STEP_BYTES = 8 * (1 + N_ACTIONS)
"""What every agent draws ahead for each step of an episode (``agent.brain``: a random action
and the tie-breaking noise of each action; the simulator the same per learner)."""
MEMINFO = Path("/proc/meminfo")


def available_bytes(meminfo: Path = MEMINFO) -> int | None:
    """The memory the machine can give new processes (``MemAvailable``); None where unknown."""
    try:
        for line in meminfo.read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def needed_bytes(processes: int, agents: int, max_steps: int) -> int:
    """A floor of what ``processes`` processes playing ``agents`` agents need."""
    return processes * PROCESS_MIB * MIB + agents * max_steps * STEP_BYTES


def check_fits(processes: int, agents: int, max_steps: int, available: int | None = None) -> None:
    """Raise ValueError, saying what is needed and what there is, where this machine cannot hold
    ``processes`` processes playing ``agents`` agents of ``max_steps`` steps."""
    available = available_bytes() if available is None else available
    needed = needed_bytes(processes, agents, max_steps)
    if available is None or needed <= available:
        return
    what = f"{processes} processes" if processes > 1 else "this process"
    raise ValueError(
        f"{agents} agents of at most {max_steps} steps need at least {needed / 2**30:.3g} GiB of "
        f"memory here ({what}), and this machine has {available / 2**30:.3g} GiB available: run "
        f"fewer agents or steps, or spread the agents over hosts (--role agents)")
