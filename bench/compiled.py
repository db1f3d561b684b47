"""rosnet-tui as `pip install` leaves it: a byte-compiled copy of the package, run ahead of the
repository.

The baselines are installed, compiled programs (ssh, nc, rostopic, the Textual library of the
bare app); rosnet-tui run from the repository with PYTHONDONTWRITEBYTECODE set (as in CI) would
compile every one of its modules on every start instead. The repository's files are not touched.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def compiled_copy(into: Path) -> Path:
    """A copy of the rosnet_tui package, byte-compiled, in *into* (returned)."""
    shutil.copytree(REPO / "rosnet_tui", into / "rosnet_tui",
                    ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(into / "rosnet_tui")],
                   check=True, capture_output=True, timeout=120)
    return into


def run_compiled(env: dict[str, str], package_dir: Path) -> dict[str, str]:
    """*env* importing rosnet_tui from *package_dir*: first on PYTHONPATH, and with
    PYTHONSAFEPATH set, since ``python -m`` would otherwise put the working directory (the
    repository, where the bench runs) ahead of it."""
    env = dict(env)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(package_dir), env.get("PYTHONPATH"))
                                        if p)
    env["PYTHONSAFEPATH"] = "1"
    return env
