"""Notes with codes: a note is text for people ending in its code in brackets
(``... outside its range [ls_start_rejected]``), so that programs (tests, aggregators, a user's
script) match the code, not the wording, and the files stay plain text."""

from __future__ import annotations

import re
from collections.abc import Iterable

_CODE = re.compile(r"\[([a-z][a-z0-9_]*)\]$")


def note(code: str, text: str) -> str:
    """``text`` tagged with ``code`` (lower case, digits and underscores)."""
    if not re.fullmatch(r"[a-z][a-z0-9_]*", code):
        raise ValueError(f"note code '{code}': lower case letters, digits and underscores only")
    return f"{text} [{code}]"


def code_of(text: str) -> str | None:
    """The code a note ends with, or None for a note without one."""
    m = _CODE.search(text.rstrip())
    return m.group(1) if m else None


def codes(notes: Iterable[str] | str | None) -> set[str]:
    """The codes of a list of notes (or of one note)."""
    if notes is None:
        return set()
    if isinstance(notes, str):
        notes = [notes]
    return {c for n in notes if (c := code_of(n))}
