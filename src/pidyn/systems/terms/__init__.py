"""Restoring-force terms: the building blocks of single-degree-of-freedom models, one file each.

A model is mass x acceleration + the sum of its terms = excitation force. Every term is one
small class: its parameters, its force (torch and NumPy through the same array code), its
regression columns (derived from the force) and, for hysteresis, the rate of its latent state.
Every force is written here once: the systems, the screening effects of the diagnosis
(``pidyn.discrepancy.effects``), the SINDy library and the hidden effects of the tests take their
forces and columns from these classes. A new force is one file here (a ``ForceTerm`` subclass,
``base.py``), found by its name when the package is imported.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

from pidyn.systems.terms.amplitude import AmplitudeSoftening
from pidyn.systems.terms.base import Array, ForceTerm, heun_along, latent_path
from pidyn.systems.terms.bouc_wen import BoucWenHysteresis
from pidyn.systems.terms.coulomb_friction import CoulombFriction
from pidyn.systems.terms.cubic_stiffness import CubicStiffness
from pidyn.systems.terms.gap_contact import GapContact
from pidyn.systems.terms.learned import LearnedForce
from pidyn.systems.terms.linear import LinearStiffness, ViscousDamping
from pidyn.systems.terms.monomial import Monomial
from pidyn.systems.terms.quadratic_damping import QuadraticDamping
from pidyn.systems.terms.quadratic_stiffness import QuadraticStiffness
from pidyn.systems.terms.steps import DampingChange, StepInTime, StiffnessLoss
from pidyn.systems.terms.stribeck import StribeckFriction
from pidyn.systems.terms.trilinear import TrilinearSpring


def _discover() -> dict[str, type[ForceTerm]]:
    """Every concrete ``ForceTerm`` with a name of its own, defined in a module of this package:
    a new term is its file."""
    found: dict[str, type[ForceTerm]] = {}
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        module = importlib.import_module(f"{__name__}.{info.name}")
        for obj in vars(module).values():
            if (
                inspect.isclass(obj)
                and issubclass(obj, ForceTerm)
                and obj.__module__ == module.__name__
                and not inspect.isabstract(obj)
                and obj.name != ForceTerm.name
            ):
                found[obj.name] = obj
    return found


TERMS: dict[str, type[ForceTerm]] = _discover()
"""Every force term by its name (``storey_terms``, ``support_terms`` and configs name them so)."""

__all__ = [
    "TERMS",
    "AmplitudeSoftening",
    "Array",
    "BoucWenHysteresis",
    "CoulombFriction",
    "CubicStiffness",
    "DampingChange",
    "ForceTerm",
    "GapContact",
    "LearnedForce",
    "LinearStiffness",
    "Monomial",
    "QuadraticDamping",
    "QuadraticStiffness",
    "StepInTime",
    "StiffnessLoss",
    "StribeckFriction",
    "TrilinearSpring",
    "ViscousDamping",
    "heun_along",
    "latent_path",
]
