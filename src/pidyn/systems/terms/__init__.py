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

from pidyn.discovery import defined_in
from pidyn.systems.terms.amplitude import AmplitudeSoftening
from pidyn.systems.terms.base import Array, ForceTerm, heun_along, latent_path, signed_sum
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

TERMS: dict[str, type[ForceTerm]] = {
    cls.name: cls for cls in defined_in(__name__, __path__, ForceTerm) if cls.name != ForceTerm.name
}
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
    "signed_sum",
]
