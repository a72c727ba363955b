"""The diagnosis's learned force as one step: trained where the residual is structured and nothing in the library explains it, kept only when it predicts the held-out part better."""

from __future__ import annotations

import logging

import numpy as np
import torch

from pidyn.data.sources import Record
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.learned_fit import fit_learned_force
from pidyn.discrepancy.residual import unexplained_force
from pidyn.discrepancy.step_reports import LearnedRefusal
from pidyn.reporting import nrmse
from pidyn.simulate import simulate_response
from pidyn.systems.terms import LearnedForce

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- in the diagnosis
#: the name of the extension by a learned force (outside the library)
LEARNED = "learned_force"


def learned_row(structure: dict | None) -> Evidence:
    """The extension row of a learned force: its evidence is the generic f(x, x')'s."""
    st = structure or {}
    return Evidence(
        LEARNED,
        score=-st.get("delta_bic", 0.0),
        delta_bic=st.get("delta_bic"),
        explained=st.get("explained"),
        cv_gain=st.get("cv_gain"),
        heldout_gain=st.get("heldout_gain"),
        source="learned",
    )


def save_unexplained(
    path,
    record: Record,
    system,
    values: dict[str, float],
    x_raw: np.ndarray,
    fit: tuple[float, float],
    f: np.ndarray | None = None,
):
    """The force ``system`` cannot explain on the fitting part (band-limited, the ringing ends
    left out), with x and x' beside it: what a learned force term starts from. ``f``: the
    excitation paired with ``x_raw`` (default the record's)."""
    period = 2 * np.pi * np.sqrt(values["m"] / max(values.get(system.stiffness_name, 1.0), 1e-300))
    pw = unexplained_force(system, values, record.t, x_raw, record.f if f is None else f, period)
    dt = float(record.t[1] - record.t[0])
    edge = max(1, int(round(period / dt)))
    m = (record.t >= fit[0]) & (record.t <= fit[1])
    m[:edge] = False
    m[-edge:] = False
    np.savez(path, x=pw["x"][m], v=pw["v"][m], force=pw["r"][m])
    return path


def train_learned_force(
    record: Record, system, values: dict[str, float], s, fit: tuple[float, float], settings, folder
) -> tuple[dict[str, float], dict | None]:
    """The learned force (weights set in place) and the physical parameters trained further on
    the simulated response of the fitting part (``fit_learned_force``); the weights are written
    to ``folder/learned_force.pt`` (the PIDynNet checkpoint there holds the ones before this
    training). ``s``: the screening's signals; ``settings``: ``LearnedSettings``."""
    period = 2 * np.pi * np.sqrt(values["m"] / max(values.get(s.stiffness, s.k_nominal), 1e-300))
    res = fit_learned_force(
        system,
        values,
        record,
        fit,
        period,
        smoothed=(s.x, s.v),
        periods_per_segment=float(settings.periods_per_segment),
        max_evaluations=int(settings.max_evaluations),
    )
    if res is None:
        return values, None
    nets = [t.net.state_dict() for t in system.terms if isinstance(t, LearnedForce)]
    torch.save({"values": res.values, "networks": nets}, folder / "learned_force.pt")
    return res.values, {
        "note": res.note,
        "loss_before": res.loss_before,
        "loss_after": res.loss_after,
        "evaluations": res.evaluations,
        "segments": res.segments,
        "segment_seconds": res.segment_seconds,
        "seconds": res.seconds,
        "file": f"{folder.name}/learned_force.pt",
    }


def learned_predicts(
    record: Record,
    before,
    before_values: dict[str, float],
    after,
    after_values: dict[str, float],
    x_raw: np.ndarray,
    v0: float,
    held: tuple[float, float],
    substeps: int,
) -> tuple[bool, dict[str, float]]:
    """Does the model with a learned force predict the held-out part better than the model it
    extends? A network trained on the fitting part can fit it and still extrapolate wrongly
    (a trilinear spring reached further in the held-out part): kept only if it predicts better.
    The held-out part decides here, as it does for the screening's held-out rules."""
    mask = (record.t >= held[0]) & (record.t <= held[1])
    kind = "x" if record.x is not None else "a"  # an accelerometer record is judged on its accelerations
    measured = x_raw if kind == "x" else record.a[:, 0]
    errors = {}
    for key, system, vals in (("without", before, before_values), ("with", after, after_values)):
        y0 = np.zeros(system.n_state)
        y0[0], y0[1] = float(x_raw[0]), v0
        sim = simulate_response(system, vals, record, substeps, y0)[kind][:, 0]
        errors[key] = nrmse(sim[mask], measured[mask]) if np.all(np.isfinite(sim)) else float("inf")
    return bool(mask.any() and errors["with"] < errors["without"]), errors


def refuse_learned(
    record: Record,
    before,
    before_values: dict[str, float],
    after,
    after_values: dict[str, float],
    x_raw: np.ndarray,
    v0: float,
    held: tuple[float, float],
    substeps: int,
    folder,
) -> tuple[LearnedRefusal | None, dict[str, float]]:
    """Why the learned force of the run in ``folder`` is not kept (None: it is), and both
    held-out errors."""
    kept, errors = learned_predicts(
        record, before, before_values, after, after_values, x_raw, v0, held, substeps
    )
    if kept:
        return None, errors
    note = (
        f"the learned force predicts the held-out part worse (NRMSE {errors['with']:.3g}) than the model "
        f"it extends ({errors['without']:.3g}): not kept"
    )
    log.info("%s: %s", folder.name, note)
    return LearnedRefusal(LEARNED, folder.name, errors, note), errors
