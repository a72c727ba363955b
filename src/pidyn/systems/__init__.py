"""Structural systems: named residuals for the physics loss, right-hand sides for simulation."""

from pidyn.systems.base import Kinematics, StructuralSystem
from pidyn.systems.sdof import AmplitudeDependent, BoucWen, Duffing, LinearSDOF, SDOFSystem
from pidyn.systems.shear_building import ShearBuilding
from pidyn.systems.terms import TERMS, ForceTerm

__all__ = [
    "Kinematics",
    "StructuralSystem",
    "SDOFSystem",
    "LinearSDOF",
    "Duffing",
    "AmplitudeDependent",
    "BoucWen",
    "ShearBuilding",
    "ForceTerm",
    "TERMS",
]
