"""Running one sweep or task of a study as a subprocess, with the command and its exit logged."""

from __future__ import annotations

import subprocess
import time
from pathlib import Path


def run_logged(cmd: list[str], label: str, cwd: Path, launcher: str = "joblib") -> int:
    """Run ``cmd`` (a Hydra command; another ``launcher`` than joblib is appended), print it and
    how it ended; the exit code is returned, a failed sweep does not stop the study."""
    if launcher != "joblib":
        cmd = [*cmd, f"hydra/launcher={launcher}"]
    print("+", " ".join(cmd[1:]), flush=True)
    t0 = time.perf_counter()
    rc = subprocess.run(cmd, cwd=cwd).returncode
    print(f"  {label}: exit {rc} after {time.perf_counter() - t0:.0f} s", flush=True)
    return rc
