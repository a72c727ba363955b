"""The commit stamped on benchmark rows: ``+dirty`` for changed code only, ``unknown`` outside git."""

from __future__ import annotations

import shutil
import subprocess

import pytest

from pidyn.runs.provenance import code_commit


@pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")
def test_the_commit_is_dirty_for_changed_code_and_not_for_results(tmp_path):
    def git(*args: str) -> str:
        cmd = ["git", "-c", "user.name=t", "-c", "user.email=t@t", *args]
        return subprocess.run(cmd, cwd=tmp_path, check=True, capture_output=True, text=True).stdout.strip()

    assert code_commit(tmp_path) == "unknown"
    (tmp_path / "src").mkdir()
    (tmp_path / "results").mkdir()
    (tmp_path / "src" / "a.py").write_text("x = 1\n")
    (tmp_path / "results" / "table.md").write_text("| a |\n")
    git("init", "-q")
    git("add", ".")
    git("commit", "-qm", "first")
    head = git("rev-parse", "--short", "HEAD")
    assert code_commit(tmp_path) == head
    (tmp_path / "results" / "table.md").write_text("| b |\n")  # a study rewriting its own table
    assert code_commit(tmp_path) == head
    (tmp_path / "src" / "a.py").write_text("x = 2\n")
    assert code_commit(tmp_path) == head + "+dirty"
