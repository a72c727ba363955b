"""Build the extended model: the nominal system plus the named effect's force term.

A function with plain arguments, so that a config node (``_target_`` this function, the
nominal system as a nested node) rebuilds the extended model exactly.
"""

from __future__ import annotations

from pidyn.discrepancy.effects import get_effect
from pidyn.systems.sdof import SDOFSystem


def extended_system(nominal: SDOFSystem, effect: str, effect_params: dict, context: dict,
                    held: list[str] | tuple[str, ...] = ()) -> SDOFSystem:
    """``nominal`` + the ``effect`` term initialised at ``effect_params``; ``learned_force``
    adds a network f(x, x'), started from the force saved at ``effect_params.init_from``.

    ``held``: effect parameters kept at their start, not identified again. A change time
    located by the global search over the record (``t_d``, with its interval) is held: a
    gradient or local search from it only drifts, because the response depends on t_d
    through the sharp step alone and the fit has a local minimum at every half cycle."""
    if not isinstance(nominal, SDOFSystem):
        raise TypeError(f"the discrepancy library extends single-degree-of-freedom models, not {type(nominal).__name__}")
    if effect == "learned_force":  # outside the library: a network f(x, x') (a universal differential equation)
        from pidyn.systems.terms import LearnedForce

        ctx = dict(context)
        term = LearnedForce(ctx.get("x_scale", 1.0), ctx.get("v_scale", 1.0), ctx.get("f_scale", 1.0),
                            **{k: int(v) for k, v in dict(effect_params).items() if k in ("hidden", "depth", "seed")})
        start = dict(effect_params).get("init_from")
        if start:  # the force the model could not explain, saved in the run folder: the network's start
            import numpy as np

            with np.load(start) as d:
                term.fit_to(d["x"], d["v"], d["force"])
        return nominal.with_term(term)
    term = get_effect(effect).term(dict(effect_params), dict(context))
    names = {sp.name for sp in term.specs()}
    unknown = set(held) - names
    if unknown:
        raise ValueError(f"effect '{effect}': cannot hold {sorted(unknown)}; its parameters are {sorted(names)}")
    return nominal.with_term(term, params={n: {"trainable": False} for n in held} or None)
