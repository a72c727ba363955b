"""Build the extended model: the nominal system plus the named effect's force term.

A function with plain arguments, so that a config node (``_target_`` this function, the
nominal system as a nested node) rebuilds the extended model exactly.
"""

from __future__ import annotations

from pidyn.discrepancy.effects import get_effect
from pidyn.systems.sdof import SDOFSystem


def extended_system(nominal: SDOFSystem, effect: str, effect_params: dict, context: dict) -> SDOFSystem:
    """``nominal`` + the ``effect`` term initialised at ``effect_params``."""
    if not isinstance(nominal, SDOFSystem):
        raise TypeError(f"the discrepancy library extends single-degree-of-freedom models, not {type(nominal).__name__}")
    term = get_effect(effect).term(dict(effect_params), dict(context))
    return nominal.with_term(term)
