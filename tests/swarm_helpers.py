"""Shared helpers of the swarm tests: start launch/swarm.py as a real process tree and read its run."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SWARM = ROOT / "launch" / "swarm.py"


def swarm_command(out: Path, *options: str) -> list[str]:
    return [sys.executable, str(SWARM), "--out", str(out), "--no-progress", *options]


def run_swarm(out: Path, *options: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """Run a swarm to completion; the whole process tree is its own session."""
    return subprocess.run(
        swarm_command(out, *options), cwd=ROOT, capture_output=True, text=True, timeout=timeout,
        start_new_session=True, env={**os.environ, "NNQL_LOG": "WARNING"},
    )


def start_swarm(out: Path, *options: str) -> subprocess.Popen:
    """Start a swarm in its own process group (so a test can signal it like a terminal would)."""
    return subprocess.Popen(
        swarm_command(out, *options), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True,
    )


def group_pids(pgid: int) -> list[int]:
    """The live (non-zombie) processes of a process group."""
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        state, pgrp = fields[0], int(fields[2])
        if pgrp == pgid and state != "Z":
            pids.append(int(entry.name))
    return pids
