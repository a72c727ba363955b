"""The kinds of structure the diagnosis loop runs on, one file each (``pidyn.discrepancy.loop``).

Every module of this package holds one ``Subject``; the package finds them when it is
imported, so a structure is added to the diagnosis by adding its file.
"""

from __future__ import annotations

from typing import Any

from pidyn.discovery import defined_in
from pidyn.discrepancy.case import check_diagnosable
from pidyn.discrepancy.loop import Subject

SUBJECTS: list[type[Subject]] = defined_in(__name__, __path__, Subject)
"""Every subject, by module name."""


def subject_for(system: Any) -> type[Subject]:
    """The subject that diagnoses ``system``, or a named refusal."""
    check_diagnosable(system)
    for subject in SUBJECTS:
        if subject.takes(system):
            return subject
    takes = ", ".join(s.takes_words for s in SUBJECTS)
    raise ValueError(
        f"system '{system.name}': the diagnosis takes {takes}; diagnose this structure as one of them"
    )


__all__ = ["SUBJECTS", "subject_for"]
