"""Where the ``rerun`` command of this environment is: for merging parts and serving saved runs."""

import importlib.util
import os
import shutil
import sys
from pathlib import Path


def rerun_binary() -> list[str]:
    """The ``rerun`` command of this environment: the native binary of the ``rerun_cli`` package
    (no Python start-up), else the script next to the interpreter, else on PATH."""
    spec = importlib.util.find_spec("rerun_cli")
    if spec is not None and spec.origin:
        native = Path(spec.origin).parent / "rerun"
        if native.is_file() and os.access(native, os.X_OK):
            return [str(native)]
    beside = Path(sys.executable).parent / "rerun"
    if beside.exists():
        return [str(beside)]
    found = shutil.which("rerun")
    return [found] if found else [sys.executable, "-m", "rerun_cli"]
