"""Whether this machine can hold the part of a run it is asked to start: the memory its
processes need, roughly, against what the machine has available (``/proc/meminfo``), and the
agent processes a core can carry.

A run that does not fit would otherwise start and fail slowly: processes killed for memory and
restarted for ever, a machine swapping to a crawl, or agents that time out joining a hub too
busy to let them in. Both figures are floors measured on a 2-core VM (docs/performance.md,
"How many agents a machine holds"), so a refused run would not have fitted.
"""

import os
from pathlib import Path

from nnql_swarm.protocol.actions import N_ACTIONS

MIB = 2**20
SHARED_MIB = 40
"""What every process of a run maps from the one server they are forked from
(``launch.processes``: the interpreter, Zenoh, numpy, our modules), counted once: an agent's
resident memory is 42 to 45 MiB, nearly all of it shared."""
PROCESS_MIB = 8
"""What each process adds of its own (its private pages: ``Private_Dirty`` of an agent of a
64-agent swarm, 8 MiB; 1,000 processes of a 1,024-agent swarm took 12 MiB each)."""
STEP_BYTES = 8 * (1 + N_ACTIONS)
"""What every agent draws ahead for each step of an episode (``agent.brain``: a random action
and the tie-breaking noise of each action; the simulator the same per learner)."""
AGENTS_PER_CORE = 256
"""The most agent processes a core carries: 512 agents on 2 cores start and finish with every
intent answered after the first episode; 1,024 do not (about 40 of them time out joining the
hub while the others' standing queries, n squared, go through it)."""
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


def usable_cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0))


def needed_bytes(processes: int, agents: int, max_steps: int) -> int:
    """A floor of what ``processes`` processes playing ``agents`` agents need."""
    return (SHARED_MIB + processes * PROCESS_MIB) * MIB + agents * max_steps * STEP_BYTES


def check_fits(processes: int, agents: int, max_steps: int, *, own_processes: bool = True,
               available: int | None = None, cores: int | None = None) -> None:
    """Raise ValueError, saying what is needed and what there is, where this machine cannot hold
    ``processes`` processes playing ``agents`` agents of ``max_steps`` steps, each agent in a
    process of its own unless not ``own_processes`` (``--in-process``)."""
    available = available_bytes() if available is None else available
    needed = needed_bytes(processes, agents, max_steps)
    if available is not None and needed > available:
        what = f"{processes} processes" if processes > 1 else "this process"
        raise ValueError(
            f"{agents} agents of at most {max_steps} steps need at least {needed / 2**30:.3g} "
            f"GiB of memory here ({what}), and this machine has {available / 2**30:.3g} GiB "
            f"available: run fewer agents or steps, or spread the agents over hosts "
            f"(--role agents)")
    cores = usable_cores() if cores is None else cores
    if own_processes and agents > AGENTS_PER_CORE * cores:
        raise ValueError(
            f"{agents} agent processes need at least {-(-agents // AGENTS_PER_CORE)} cores here (at most {AGENTS_PER_CORE} a core), "
            f"and this machine has {cores}: run fewer agents, or spread them over hosts "
            f"(--role agents)")
