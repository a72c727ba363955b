"""Refinement: output error over shooting segments with exact Jacobians, and intervals."""

from pidyn.refine.problem import Channel, ShootingProblem, record_channels, segment_bounds
from pidyn.refine.setup import RefineSettings, initial_states
from pidyn.refine.stage import RefineResult, refine

__all__ = [
    "Channel",
    "ShootingProblem",
    "record_channels",
    "segment_bounds",
    "RefineResult",
    "RefineSettings",
    "initial_states",
    "refine",
]
