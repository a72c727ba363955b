"""The library of candidate effects a nominal model may be missing, one file each.

Every module of this package but ``base`` holds one effect (an ``Effect`` subclass); the package
finds them when it is imported, so an effect is added by adding its file. ``EFFECTS`` holds every
effect by name in the library's order, ``LIBRARY`` those screened by default.
"""

from __future__ import annotations

from pidyn.discovery import defined_in
from pidyn.discrepancy.effects.base import Candidate, Effect, Signals


def _discover() -> list[Effect]:
    """One instance of every effect of this package's modules, in the library's order."""
    return sorted((cls() for cls in defined_in(__name__, __path__, Effect)), key=lambda e: (e.order, e.name))


EFFECTS: dict[str, Effect] = {e.name: e for e in _discover()}
"""Every candidate effect by name; ``none`` is the verdict when none of them is needed."""

LIBRARY: dict[str, Effect] = {n: e for n, e in EFFECTS.items() if e.library}
"""The effects screened by default (``diagnosis.effects`` empty)."""


def get_effect(name: str) -> Effect:
    if name not in EFFECTS:
        raise ValueError(f"unknown effect '{name}'; choose from {sorted(EFFECTS)} (or 'none')")
    return EFFECTS[name]


__all__ = ["EFFECTS", "LIBRARY", "Candidate", "Effect", "Signals", "get_effect"]
