"""Build the extended model: the nominal system plus the named effect's force term.

A function with plain arguments, so that a config node (``_target_`` this function, the
nominal system as a nested node) rebuilds the extended model exactly.
"""

from __future__ import annotations

import copy
from typing import Any

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf

from pidyn.discrepancy.effects import get_effect
from pidyn.discrepancy.evidence import Evidence
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import LearnedForce


def extended_system(
    nominal: SDOFSystem,
    effect: str,
    effect_params: dict,
    context: dict,
    held: list[str] | tuple[str, ...] = (),
) -> SDOFSystem:
    """``nominal`` + the ``effect`` term initialised at ``effect_params``; ``learned_force``
    adds a network f(x, x'), started from the force saved at ``effect_params.init_from``.

    ``held``: effect parameters kept at their start, not identified again. A change time
    located by the global search over the record (``t_d``, with its interval) is held: a
    gradient or local search from it only drifts, because the response depends on t_d
    through the sharp step alone and the fit has a local minimum at every half cycle."""
    if not isinstance(nominal, SDOFSystem):
        raise TypeError(
            f"the discrepancy library extends single-degree-of-freedom models, not {type(nominal).__name__}"
        )
    # outside the library: a network f(x, x') (a universal differential equation)
    if effect == "learned_force":
        ctx = dict(context)
        term = LearnedForce(
            ctx.get("x_scale", 1.0),
            ctx.get("v_scale", 1.0),
            ctx.get("f_scale", 1.0),
            **{k: int(v) for k, v in dict(effect_params).items() if k in ("hidden", "depth", "seed")},
        )
        start = dict(effect_params).get("init_from")
        if start:  # the force the model could not explain, saved in the run folder: the network's start
            with np.load(start) as d:
                term.fit_to(d["x"], d["v"], d["force"])
        return nominal.with_term(term)
    term = get_effect(effect).term(dict(effect_params), dict(context))
    names = {sp.name for sp in term.specs()}
    unknown = set(held) - names
    if unknown:
        raise ValueError(
            f"effect '{effect}': cannot hold {sorted(unknown)}; its parameters are {sorted(names)}"
        )
    return nominal.with_term(term, params={n: {"trainable": False} for n in held} or None)


# ---------------------------------------------------------------------- config nodes
# A model of the diagnosis is a plain config node (``_target_`` + arguments) so that every
# run folder rebuilds it exactly; these helpers build and edit such nodes.

#: the ``_target_`` of an extended model's node
EXTENSION = "pidyn.discrepancy.extend.extended_system"


def system_node(node: Any, inits: dict[str, float], mass: float, identify_mass: bool) -> dict:
    """A nominal system's config node with data-driven initial values and the mass setting."""
    out = _plain(node)
    out["mass"] = float(mass)
    out["identify_mass"] = bool(identify_mass)
    params = dict(out.get("params") or {})
    for n, v in inits.items():
        if n == "m":
            continue
        params[n] = {**dict(params.get(n) or {}), "init": float(v)}
    out["params"] = params
    return out


def check_fit(values: dict[str, float], row: Evidence, k: int) -> dict[str, float] | None:
    """The extended model as the output-error check fitted it: the current model's ``values``
    (at the first step with the check's refit of the nominal parameters) and the effect's
    estimate; None when the check gave no numbers."""
    effect = {n: float(v) for n, v in row.parameters.items() if not isinstance(v, str)}
    if not effect:
        return None
    return {**values, **_refit(row, k), **effect}


def _refit(row: Evidence, k: int) -> dict[str, float]:
    """The check's refit of the nominal parameters, which the first step starts from."""
    return {n: v for n, v in row.nominal_refit.items() if v > 0} if k == 1 else {}


def extension_node(
    node: dict, values: dict[str, float], cause: str, row: Evidence, context: dict, k: int, mass_known: bool
) -> dict:
    """The node of step ``k``'s model: the current model (its values; at the first step the
    screening's refit of the nominal parameters) extended with ``cause`` started at the
    screening's estimate (``row``); ``context`` is ``Signals.context()``."""
    refit = _refit(row, k)
    inner = node_with_values(node, {**values, **refit})
    if k == 1:
        inner = system_node(inner, refit, refit.get("m", values["m"]), not mass_known)
    out = {
        "_target_": EXTENSION,
        "nominal": inner,
        "effect": cause,
        "effect_params": {n: (v if isinstance(v, str) else float(v)) for n, v in row.parameters.items()},
        "context": context,
    }
    if row.change is not None:  # located over the record, with an interval: held (see extended_system)
        out["held"] = ["t_d"]
    return out


def release_held(node: Any) -> dict:
    """A copy of a system node with every held effect parameter free again (the polish and the
    output-error check refine a located change time from its located value)."""
    node = _plain(node)
    if node.get("_target_") == EXTENSION:
        node.pop("held", None)
        node["nominal"] = release_held(node["nominal"])
    return node


def build_system(node: Any) -> SDOFSystem:
    """The system a node describes."""
    return hydra.utils.instantiate(OmegaConf.create(_plain(node)))


def node_with_values(node: Any, values: dict[str, float]) -> dict:
    """A copy of a (possibly nested) system node started from ``values``: the nominal
    parameters as ``params.<name>.init``, each effect's as its ``effect_params``."""
    node = _plain(node)
    if node.get("_target_") == EXTENSION:
        node["nominal"] = node_with_values(node["nominal"], values)
        node["effect_params"] = {n: float(values.get(n, v)) for n, v in node["effect_params"].items()}
        return node
    params = dict(node.get("params") or {})
    for n in list(params):
        if n in values and n != "m":
            params[n] = {**dict(params[n] or {}), "init": float(values[n])}
    node["params"] = params
    return node


def _plain(node: Any) -> dict:
    """A deep plain-dict copy of a node (a DictConfig resolved)."""
    out = OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else copy.deepcopy(node)
    assert isinstance(out, dict)
    return out
