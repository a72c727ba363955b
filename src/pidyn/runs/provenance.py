"""Which code produced a result: the checkout's commit, stamped on benchmark rows so that rows
from a resumed study that spans several commits stay told apart."""

from __future__ import annotations

import subprocess
from pathlib import Path

#: what counts as code: a study rewrites its own tables under experiments/results as it goes
CODE_PATHS = ("src", "*.py", "conf")


def code_commit(root: Path | str) -> str:
    """The short commit of the checkout at ``root``, with ``+dirty`` when its code has
    uncommitted changes; ``unknown`` outside a git checkout (an installed wheel)."""
    try:
        head = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, cwd=root, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS],
            capture_output=True,
            text=True,
            cwd=root,
        ).stdout.strip()
        return head + ("+dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
