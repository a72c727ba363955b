"""Refinement: output error over shooting segments with exact Jacobians, and intervals.

The settings load with the package; the solver (torch, the compiled simulation) on the first use
of a name that needs it, so that the config layer reads ``RefineSettings`` in a fraction of a second.
"""

from importlib import import_module
from typing import Any

from pidyn.refine.settings import RefineSettings

#: the package's names and the module each lives in
_HOMES = {
    "Channel": "problem",
    "ShootingProblem": "problem",
    "record_channels": "problem",
    "segment_bounds": "problem",
    "initial_states": "setup",
    "RefineResult": "stage",
    "refine": "stage",
}


def __getattr__(name: str) -> Any:
    """A name of the solver, imported on first use (PEP 562)."""
    if name in _HOMES:
        # lazy: the solver's modules load torch (seconds); the settings alone do not need them
        return getattr(import_module(f"pidyn.refine.{_HOMES[name]}"), name)
    raise AttributeError(f"module 'pidyn.refine' has no attribute '{name}'")


__all__ = ["RefineSettings", *_HOMES]
