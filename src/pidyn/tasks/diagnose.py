"""The diagnosis task: what does the nominal model get wrong, why, and what does fixing it gain?

1. identify the nominal model on the fitting part (PIDynNet, then optionally an output-error
   polish);
2. compute the force it cannot explain (figures: over time, against x and x', spectrum);
3. screen the effect library against it (``pidyn.discrepancy.screening``) and name the cause,
   or ``none``;
4. extend the model with the named effect and identify it again with PIDynNet (its parameters
   trainable in the physics loss; hysteresis brings a latent state through the LNN);
5. simulate nominal and extended models over the held-out part and compare.

The nominal and extended identifications are ordinary PIDynNet runs in ``nominal/`` and
``extended/``, each with its resolved ``config.yaml``.
"""

from __future__ import annotations

import copy
import logging
import time
from pathlib import Path
from typing import Any

import hydra
import numpy as np
from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.baselines.least_squares import output_error
from pidyn.data.sources import Record
from pidyn.discrepancy.changes import heldout_check, locate_change, running_estimate
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.report import (plot_learned_force, plot_ranking, plot_residual, plot_response,
                                     plot_running_estimate, write_report)
from pidyn.discrepancy.residual import band_limited, dominant_period, unexplained_force
from pidyn.discrepancy.screening import Thresholds, screen, weak_system
from pidyn.discrepancy.weak_form import WeakForm, smooth_signals, velocity_noise
from pidyn.reporting import nrmse, write_json
from pidyn.systems.sdof import SDOFSystem
from pidyn.tasks.train import build_record, identify, simulate_identified

log = logging.getLogger(__name__)


def split_spans(record: Record, fit_share: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Fitting and held-out time spans: the record's own split if it has one, else a share."""
    sp = (record.meta or {}).get("split")
    if sp:
        return (float(sp["fit"][0]), float(sp["fit"][1])), (float(sp["heldout"][0]), float(sp["heldout"][1]))
    if not 0.1 <= fit_share <= 0.95:
        raise ValueError(f"diagnosis.fit_share must lie in [0.1, 0.95], got {fit_share}")
    t0, t1 = float(record.t[0]), float(record.t[-1])
    cut = t0 + fit_share * (t1 - t0)
    return (t0, cut), (cut, t1)


def _stiffness_name(system: SDOFSystem) -> str:
    names = [s.name for s in system.param_specs()]
    for n in ("k", "k1"):
        if n in names:
            return n
    raise ValueError(f"nominal system '{system.name}' has no linear stiffness 'k' or 'k1' to extend")


def _system_node(node: DictConfig, inits: dict[str, float], mass: float, identify_mass: bool) -> dict:
    """The nominal system's config with data-driven initial values and the mass setting."""
    out = OmegaConf.to_container(node, resolve=True)
    assert isinstance(out, dict)
    out["mass"] = float(mass)
    out["identify_mass"] = bool(identify_mass)
    params = dict(out.get("params") or {})
    for n, v in inits.items():
        if n == "m":
            continue
        params[n] = {**dict(params.get(n) or {}), "init": float(v)}
    out["params"] = params
    return out


def _sub_cfg(cfg: DictConfig, system_node: dict, out_dir: Path, fit: tuple[float, float]) -> DictConfig:
    c = copy.deepcopy(cfg)
    with open_dict(c):
        c.system = system_node
        c.paths.output_dir = str(out_dir)
        c.data.windows.t_start = fit[0]
        c.data.windows.t_end = fit[1]
        c.baselines = {"run": [], "cramer_rao": False}
        c.model.refine = {"method": "none"}  # the diagnosis polishes with output error itself (diagnosis.polish)
        if cfg.diagnosis.get("ls_init") is not None:
            c.model.schedule.ls_init = cfg.diagnosis.ls_init
    out_dir.mkdir(parents=True, exist_ok=True)
    OmegaConf.save(c, out_dir / "config.yaml", resolve=False)
    return c


def _polish(record: Record, system: SDOFSystem, values: dict[str, float], dcfg: DictConfig,
            fit: tuple[float, float]) -> tuple[dict[str, float], str]:
    """Output-error least squares on (part of) the fitting span, from ``values``."""
    seg_end = fit[1] if dcfg.polish_seconds is None else min(fit[1], fit[0] + float(dcfg.polish_seconds))
    seg = record.segment(fit[0], seg_end)
    trainable = {s.name for s in system.param_specs() if s.trainable}
    res = output_error(seg, system, init={k: v for k, v in values.items() if k in trainable},
                       substeps=int(dcfg.substeps), max_nfev=int(dcfg.polish_max_nfev))
    out = dict(values)
    out.update(res.params)
    return out, f"output error on {seg.t[0]:.4g}-{seg.t[-1]:.4g} s: {res.note}, {res.seconds:.1f} s"


def diagnose(cfg: DictConfig, record: Record | None = None) -> dict[str, Any]:
    """What the nominal model ``cfg.system`` misses on ``record`` (default: built from
    ``cfg.data``); writes diagnosis.json, report.md and figures to the run folder."""
    t_wall = time.perf_counter()
    run_dir = Path(cfg.paths.output_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    dcfg = cfg.diagnosis
    wanted = list(dcfg.effects) if dcfg.get("effects") else list(EFFECTS)
    unknown = set(wanted) - set(EFFECTS)
    if unknown:
        raise ValueError(f"diagnosis.effects: unknown effect(s) {sorted(unknown)}; the library has {sorted(EFFECTS)}")
    effects = {n: EFFECTS[n] for n in wanted}
    thresholds = Thresholds(**OmegaConf.to_container(dcfg.thresholds, resolve=True))  # type: ignore[arg-type]

    base: SDOFSystem = hydra.utils.instantiate(cfg.system)
    if not isinstance(base, SDOFSystem):
        raise ValueError(f"diagnosis needs a single-degree-of-freedom nominal system, got '{base.name}'")
    already = {t.name for t in base.terms} & set(effects)
    if already:  # an effect the nominal model already has cannot be what it misses
        log.info("not screening %s: already in the nominal model", sorted(already))
        effects = {n: e for n, e in effects.items() if n not in already}
    record = build_record(cfg, base) if record is None else record
    if record.excitation != base.excitation:
        base = hydra.utils.instantiate(cfg.system, excitation=record.excitation)
    mass = cfg.data.get("mass", 1.0)
    mass_known = mass is not None
    if not mass_known and record.excitation == "ground":
        raise ValueError("data.mass is null, but a ground-excited record cannot reveal the mass "
                         "(m x'' + ... = -m ag is homogeneous in m): give the mass")
    fit, held = split_spans(record, float(dcfg.fit_share))
    stiff = _stiffness_name(base)
    log.info("diagnosing '%s' with nominal '%s': fit %.4g-%.4g s, held out %.4g-%.4g s",
             record.name, base.name, *fit, *held)

    # --- signals, time scale and a data-driven starting point for the nominal parameters
    x_raw = record.x[:, 0]
    fit_mask = (record.t >= fit[0]) & (record.t <= fit[1])
    period = dominant_period(record.t[fit_mask], x_raw[fit_mask])
    values0 = {s.name: s.init for s in base.param_specs()}
    if mass_known:
        values0["m"] = float(mass)

    def signals(period_: float, k_nom: float) -> tuple[Signals, WeakForm]:
        v_raw = None if record.v is None else record.v[:, 0]
        xs, vs = smooth_signals(record.t, x_raw, v_raw, period_)
        return (Signals(record.t, xs, vs, values0.get("m", 1.0), k_nom, stiff, t_fit_end=fit[1],
                        v_noise=velocity_noise(record.t, x_raw, v_raw, period_)),
                WeakForm.for_record(record.t, period_))

    s, weak = signals(period, values0[stiff])
    start = screen(base, values0, s, record.f, x_raw, weak, fit[1], mass_known, effects={}, thresholds=thresholds)
    values0.update(start.nominal_params)
    if values0.get(stiff, 0) > 0 and values0.get("m", 0) > 0:
        period = 2 * np.pi * np.sqrt(values0["m"] / values0[stiff])
        s, weak = signals(period, values0[stiff])
        start = screen(base, values0, s, record.f, x_raw, weak, fit[1], mass_known, effects={}, thresholds=thresholds)
        values0.update(start.nominal_params)
    log.info("weak-form starting point: %s (natural period %.4g s)", _fmt(values0), period)

    # --- 1. nominal identification (PIDynNet, then polish)
    nominal_node = _system_node(cfg.system, {k: v for k, v in values0.items() if v > 0},
                                values0["m"] if "m" in values0 else 1.0, not mass_known)
    if record.excitation != OmegaConf.select(cfg, "system.excitation", default=record.excitation):
        nominal_node["excitation"] = record.excitation
    nom_metrics, nom_obj = identify(_sub_cfg(cfg, nominal_node, run_dir / "nominal", fit), record)
    nominal: SDOFSystem = nom_obj["system"]
    nominal_values = nom_obj["module"].net.params.as_floats()
    polish_note = None
    if dcfg.polish:
        nominal_values, polish_note = _polish(record, nominal, nominal_values, dcfg, fit)
    s, weak = signals(period, nominal_values[stiff])
    s.mass = nominal_values["m"]

    # --- 2-3. what the nominal model cannot explain, and which effect explains it
    sc = screen(nominal, nominal_values, s, record.f, x_raw, weak, fit[1], mass_known, effects, thresholds)
    pointwise = unexplained_force(nominal, nominal_values, record.t, x_raw, record.f, period)
    forced = dcfg.get("force_effect")
    cause = forced or sc.cause
    log.info("screening: %s", ", ".join(f"{r['effect']} {r['score']:.1f}" for r in sc.ranking[:4]))

    # --- 3b. does the nominal model hold on the held-out part? if not, when did the structure change?
    def free_run(system: SDOFSystem, values: dict[str, float]) -> np.ndarray:
        """From the measured initial state over the whole record."""
        return simulate_identified(system, values, record, x0=float(x_raw[0]), v0=float(s.v[0]),
                                   substeps=int(dcfg.substeps))[:, 0]

    x_nom = free_run(nominal, nominal_values)
    held_mask = (record.t >= held[0]) & (record.t <= held[1])
    check = heldout_check(x_raw, x_nom, fit_mask, held_mask, float(np.std(x_raw - s.x)),
                          threshold=float(dcfg.changes.heldout_ratio))
    log.info("%s", check.sentence())
    change_row = None
    time_effects = {n: p_ for n, p_ in {"stiffness_loss": stiff, "damping_change": "c"}.items()
                    if n in effects and p_ in nominal_values}
    if not forced and time_effects and ((check.failed and sc.cause is None) or sc.cause in time_effects):
        change, fit, held = _locate_change(nominal, nominal_values, s, record, x_raw, weak, fit, held, mass_known,
                                           {n: p_ for n, p_ in time_effects.items() if sc.cause in (None, n)},
                                           thresholds, bool(check.failed and sc.cause is None))
        if change is not None:
            cause = change.effect
            change_row = {"effect": change.effect, "parameters": change.effect_parameters(),
                          "nominal_refit": {}, "score": -change.delta_bic, "change": change}
            log.info("%s", change.sentence())
            fit_mask = (record.t >= fit[0]) & (record.t <= fit[1])
            held_mask = (record.t >= held[0]) & (record.t <= held[1])

    # --- 4. extended model(s): extend, screen the extended model again, until nothing more
    #        passes the evidence thresholds or diagnosis.max_effects is reached
    learn = bool(dcfg.get("learn_unexplained", True)) and not forced
    if cause is None and learn and (sc.verdict == "unexplained" or check.failed):
        cause = LEARNED  # structured, but nothing in the library explains it: learn the force
    row = None if cause is None else (_learned_row(sc) if cause == LEARNED else
                                      change_row or next(r for r in sc.ranking if r["effect"] == cause))
    ext = _extend_until_explained(cfg, record, nominal_node, nominal_values, cause, row, s, weak, x_raw, fit,
                                  effects, thresholds, mass_known, bool(forced))
    ext_system, ext_values, ext_metrics = ext["system"], ext["values"], ext["metrics"]
    causes = ext["causes"] if dcfg.extend else ([] if cause is None else [cause])
    learned = LEARNED in causes
    causes = [c for c in causes if c != LEARNED]

    # --- 5. held-out gain
    x_ext = free_run(ext_system, ext_values) if ext_system is not None else None
    gain = {"metric": "heldout_nrmse_x", "nominal": nrmse(x_nom[held_mask], x_raw[held_mask]),
            "extended": None if x_ext is None else nrmse(x_ext[held_mask], x_raw[held_mask])}
    if record.clean is not None:
        xc = record.clean.x[:, 0]
        gain["nominal_vs_clean"] = nrmse(x_nom[held_mask], xc[held_mask])
        gain["extended_vs_clean"] = None if x_ext is None else nrmse(x_ext[held_mask], xc[held_mask])

    effect_params: dict[str, Any] = {}
    if ext_values is not None and ext_system is not None:
        nominal_names = {sp.name for sp in nominal.param_specs()}
        effect_params = {k: v for k, v in ext_values.items() if k not in nominal_names}
    if change_row is not None:
        ch = change_row["change"]
        effect_params["t_change"] = effect_params.get("t_d", ch.t_change)
        effect_params["t_change_ci95"] = list(ch.ci95)
    verdict = ("discrepancy" if causes or (cause is not None and cause != LEARNED) else
               "unexplained" if learned or check.failed or sc.verdict == "unexplained" else "none")
    cause = causes[0] if causes else (None if cause == LEARNED else cause)
    truth = dict(record.meta.get("hidden_params") or {}) if "hidden_effect" in record.meta else None
    diagnosis = {
        "nominal": nominal.describe(nominal_values),
        "verdict": verdict,
        "cause": cause,
        "causes": causes,
        "steps": ext["steps"],
        "learned_force": learned,
        "structure": {k: v for k, v in sc.structure.items()},
        "heldout_check": check.__dict__,
        "change": None if change_row is None else change_row["change"].to_dict(),
        "forced": bool(forced),
        "ranking": sc.ranking,
        "extended": ext_system.describe(ext_values) if ext_system is not None else None,
        "parameters": effect_params,
        "nominal_parameters": nominal_values,
        "extended_parameters": ext_values,
        "gain": gain,
        "split": {"fit": list(fit), "heldout": list(held)},
        "record": record.name,
        "noise": (record.meta or {}).get("noise"),
        "natural_period": period,
        "thresholds": OmegaConf.to_container(dcfg.thresholds, resolve=True),
        "polish": {"nominal": polish_note, "extended": ext["note"]},
        "pidynnet": {"nominal_errors_pct": nom_metrics.get("error_pct"),
                     "extended_errors_pct": None if ext_metrics is None else ext_metrics.get("error_pct")},
        "hidden": None if truth is None else {"effect": record.meta.get("hidden_effect"), "parameters": truth},
        "wall_seconds": time.perf_counter() - t_wall,
    }
    write_json(run_dir / "diagnosis.json", diagnosis)
    fig = run_dir / "figures"
    fig.mkdir(exist_ok=True)
    units = (record.meta or {}).get("units", {})
    plot_response(fig / "simulation_vs_measured.png", record.t, x_raw, x_nom, x_ext, fit, held, units.get("x", "m"), period)
    explained = None
    if cause is not None:
        explained = _explained_force(nominal, nominal_values,
                                     change_row or next(r for r in sc.ranking if r["effect"] == cause), s, pointwise)
    plot_residual(fig / "residual.png", record.t, pointwise["r"], pointwise["x"], pointwise["v"], fit, cause,
                  explained, units, period)
    plot_ranking(fig / "ranking.png", sc.ranking, thresholds.min_delta_bic)
    names, A0, y = weak_system(nominal, nominal_values, s, record.f, x_raw, weak, mass_known)
    running = running_estimate(names, A0, y, weak.centers, max(4 * period, 3 * weak.dt * (2 * weak.half + 1)))
    plot_running_estimate(fig / "running_estimate.png", running, nominal_values, fit, held,
                          None if change_row is None else change_row["change"])
    if learned and ext_system is not None and ext_system.n_latent == 0:
        _plot_learned(fig / "learned_force.png", record.t, nominal, nominal_values, ext_system, ext_values, pointwise,
                      units)
    write_report(run_dir / "report.md", diagnosis, [p.name for p in sorted(fig.glob("*.png"))])
    log.info("verdict: %s%s; held-out NRMSE nominal %.4g%s", diagnosis["verdict"],
             f" ({cause})" if cause else "", gain["nominal"],
             "" if gain["extended"] is None else f", extended {gain['extended']:.4g}")
    log.info("run folder %s (%.0f s)", run_dir, diagnosis["wall_seconds"])
    return diagnosis


EXTENSION = "pidyn.discrepancy.extend.extended_system"
#: effects that cannot sit in one model together (both step at their own t_d)
EXCLUSIVE = ({"stiffness_loss", "damping_change"},)


def _extend_until_explained(cfg: DictConfig, record: Record, nominal_node: dict, nominal_values: dict[str, float],
                            cause: str | None, row: dict | None, s: Signals, weak: WeakForm, x_raw: np.ndarray,
                            fit: tuple[float, float], effects: dict, thresholds: Thresholds, mass_known: bool,
                            forced: bool) -> dict[str, Any]:
    """Extend the model with ``cause``, identify it (PIDynNet, polish), screen the extended
    model against the effects not yet in it, and repeat while one passes the thresholds, up to
    ``diagnosis.max_effects``. Each step's evidence is kept; the last model carries every
    named effect. Step k's run is in ``extended/`` (k = 1) or ``extended_<k>/``."""
    dcfg = cfg.diagnosis
    run_dir = Path(cfg.paths.output_dir)
    out: dict[str, Any] = {"system": None, "values": None, "metrics": None, "causes": [], "steps": [], "note": None}
    node, values = nominal_node, nominal_values
    limit = 1 if forced else int(dcfg.get("max_effects", 3))
    while cause is not None and row is not None and dcfg.extend:
        if row.get("score") is not None and not np.isfinite(row["score"]):
            raise ValueError(f"effect '{cause}' has no physical fit to this record ({row.get('note')})")
        k = len(out["causes"]) + 1
        refit = {n: v for n, v in row["nominal_refit"].items() if v > 0} if k == 1 else {}
        if cause == LEARNED:  # start the network at the force the current model cannot explain
            row = {**row, "parameters": {"init_from": str(_save_unexplained(run_dir / f"unexplained_{k}.npz", record,
                                                                          _current_system(node), values, x_raw, fit,
                                                                          dcfg))}}
        inner = _node_with_values(node, {**values, **refit})
        if k == 1:
            inner = _system_node(OmegaConf.create(inner), refit, refit.get("m", values["m"]), not mass_known)
        ext_node = {"_target_": EXTENSION, "nominal": inner, "effect": cause,
                    "effect_params": {n: (v if isinstance(v, str) else float(v)) for n, v in row["parameters"].items()},
                    "context": s.context()}
        folder = run_dir / ("extended" if k == 1 else f"extended_{k}")
        metrics, obj = identify(_sub_cfg(cfg, ext_node, folder, fit), record)
        system: SDOFSystem = obj["system"]
        ext_values = obj["module"].net.params.as_floats()
        if dcfg.polish:
            ext_values, out["note"] = _polish(record, system, ext_values, dcfg, fit)
        out["causes"].append(cause)
        out["steps"].append({"step": k, "effect": cause, "folder": folder.name, "equation": system.describe(ext_values),
                             "evidence": {key: row.get(key) for key in ("score", "delta_bic", "explained", "cv_gain",
                                                                        "heldout_gain", "force_share")}})
        out.update(system=system, values=ext_values, metrics=metrics)
        log.info("step %d: extended with %s: %s", k, cause, system.describe(ext_values))
        node, values = ext_node, ext_values
        if k >= limit:
            if not forced:
                log.info("stopping at diagnosis.max_effects=%d effects", limit)
            break
        if cause == LEARNED:
            break  # the learned force takes whatever is left: nothing to screen after it
        present = set(out["causes"]) | {t.name for t in system.terms}
        blocked = set().union(*[g for g in EXCLUSIVE if g & present])
        remaining = {n: e for n, e in effects.items() if n not in present | blocked}
        if not remaining:
            break
        sc = screen(system, ext_values, s, record.f, x_raw, weak, fit[1], mass_known, remaining, thresholds)
        out["steps"][-1]["next_ranking"] = [{k_: r.get(k_) for k_ in ("effect", "score", "cv_gain", "passes")}
                                            for r in sc.ranking[:4]]
        log.info("screening the extended model: %s", ", ".join(f"{r['effect']} {r['score']:.1f}"
                                                               for r in sc.ranking[:4] if r.get("score") is not None))
        cause = sc.cause
        if cause is None and sc.verdict == "unexplained" and LEARNED not in out["causes"] and dcfg.get("learn_unexplained", True):
            cause = LEARNED  # what remains is structured but no library effect: learn it
        row = None if cause is None else (_learned_row(sc) if cause == LEARNED else
                                          next(r for r in sc.ranking if r["effect"] == cause))
        if cause == LEARNED and LEARNED in out["causes"]:
            break
    return out


LEARNED = "learned_force"


def _current_system(node: dict) -> SDOFSystem:
    return hydra.utils.instantiate(OmegaConf.create(node))


def _save_unexplained(path: Path, record: Record, system: SDOFSystem, values: dict[str, float], x_raw: np.ndarray,
                      fit: tuple[float, float], dcfg: DictConfig) -> Path:
    """The force ``system`` cannot explain on the fitting part (band-limited, the ringing ends
    left out), with x and x' beside it: what a learned force term starts from."""
    period = 2 * np.pi * np.sqrt(values["m"] / max(values.get("k", values.get("k1", 1.0)), 1e-300))
    pw = unexplained_force(system, values, record.t, x_raw, record.f, period)
    dt = float(record.t[1] - record.t[0])
    edge = max(1, int(round(period / dt)))
    m = (record.t >= fit[0]) & (record.t <= fit[1])
    m[:edge] = False
    m[-edge:] = False
    np.savez(path, x=pw["x"][m], v=pw["v"][m], force=pw["r"][m])
    return path


def _learned_row(sc) -> dict:
    """The extension row of a learned force: its evidence is the generic f(x, x')'s."""
    st = sc.structure or {}
    return {"effect": LEARNED, "parameters": {}, "nominal_refit": {}, "score": -st.get("delta_bic", 0.0),
            "delta_bic": st.get("delta_bic"), "explained": st.get("explained"), "cv_gain": st.get("cv_gain"),
            "heldout_gain": st.get("heldout_gain")}


def _node_with_values(node: dict, values: dict[str, float]) -> dict:
    """A copy of a (possibly nested) system node started from ``values``: the nominal
    parameters as ``params.<name>.init``, each effect's as its ``effect_params``."""
    node = copy.deepcopy(OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node)
    if node.get("_target_") == EXTENSION:
        node["nominal"] = _node_with_values(node["nominal"], values)
        node["effect_params"] = {n: float(values.get(n, v)) for n, v in node["effect_params"].items()}
        return node
    params = dict(node.get("params") or {})
    for n in list(params):
        if n in values and n != "m":
            params[n] = {**dict(params[n] or {}), "init": float(values[n])}
    node["params"] = params
    return node


def _locate_change(nominal: SDOFSystem, values: dict[str, float], s: Signals, record: Record, x_raw: np.ndarray,
                   weak: WeakForm, fit: tuple[float, float], held: tuple[float, float], mass_known: bool,
                   candidates: dict[str, str], th: Thresholds, whole_record: bool):
    """A step in stiffness or damping: its time, interval and size, and the split to measure it on.

    ``whole_record`` (the nominal model failed on the held-out part): search every row of the
    record; a change found late or after the split moves the split to halfway between the
    change and the record's end, the change is then estimated again on the new fitting part
    only, and the gain is measured on the rest, which no fit has used. Otherwise the search
    runs on the fitting part (the screening already named the time-varying effect)."""
    names, A0, y = weak_system(nominal, values, s, record.f, x_raw, weak, mass_known)
    w = 2 * weak.half + 1
    t_first, t_last = weak.t[weak.starts], weak.t[weak.starts + w - 1]

    def search(end: float):
        rows = t_last <= end + 1e-9
        n_eff = max(rows.sum() / weak.rows_per_independent, 2.0)
        return locate_change(names, A0, y, t_first, t_last, rows, s.x, s.v, s.t, weak, n_eff, candidates, values)

    change = search(float(record.t[-1]) if whole_record else fit[1])
    if change is None or change.delta_bic > -th.min_delta_bic or change.explained < th.min_cv_gain:
        log.info("no step in %s explains the residual%s", " or ".join(sorted(set(candidates.values()))),
                 "" if change is None else f" (best: {change.sentence()}, dBIC {change.delta_bic:.1f})")
        return None, fit, held
    if whole_record:
        cut = max(fit[1], change.t_change + 0.5 * (float(record.t[-1]) - change.t_change))
        if cut > fit[1]:
            log.info("the change lies at %.4g s, beyond the fitting part: fitting now %.4g-%.4g s, held out %.4g-%.4g s",
                     change.t_change, fit[0], cut, cut, held[1])
            fit, held = (fit[0], cut), (cut, held[1])
        again = search(fit[1])
        change = again if again is not None else change
    return change, fit, held


def _plot_learned(path: Path, t: np.ndarray, nominal: SDOFSystem, nominal_values: dict[str, float], ext: SDOFSystem,
                  ext_values: dict[str, float], pw: dict[str, np.ndarray], units: dict) -> None:
    """The extended model's restoring force minus the nominal one (the learned force plus the
    shift of the nominal parameters that came with it) on the residual's band-limited signals."""
    x, v = pw["x"], pw["v"]  # on the record's samples: a time-dependent term (a change) evaluates right
    dev = ext.restoring_force(t, x, v, None, ext_values) - nominal.restoring_force(t, x, v, None, nominal_values)
    gx = np.linspace(x.min(), x.max(), 60)
    gv = np.linspace(v.min(), v.max(), 60)
    X, V = np.meshgrid(gx, gv)
    t_end = float(t[-1])  # the surface: the model as it stands at the end of the record
    F = (ext.restoring_force(t_end, X, V, None, ext_values) - nominal.restoring_force(t_end, X, V, None, nominal_values))
    edge = max(1, len(x) // 50)
    inner = slice(edge, len(x) - edge)  # the band-limited ends ring
    plot_learned_force(path, x[inner], v[inner], pw["r"][inner], dev[inner], {"x": X, "v": V, "f": F}, units)


def _explained_force(nominal: SDOFSystem, values: dict[str, float], row: dict, s: Signals,
                     pw: dict[str, np.ndarray]) -> np.ndarray:
    """What the screening's fit says the residual is: the effect's force plus the change it
    brings to the nominal parameters (which had absorbed part of the effect), on the same
    band-limited signals as the residual."""
    from pidyn.discrepancy.effects import bouc_wen_z

    p = {**values, **row["nominal_refit"], **row["parameters"]}
    term = EFFECTS[row["effect"]].term(row["parameters"], s.context())
    x, v = pw["x"], pw["v"]
    z = bouc_wen_z(x, p["beta"], p["gamma"], p["n"]) if term.n_latent else None
    change = nominal.restoring_force(s.t, x, v, None, values) - nominal.restoring_force(s.t, x, v, None, p)
    inertia = (p["m"] - values["m"]) * pw["a"]  # nonzero only when the mass is identified
    total = term.force(s.t, x, v, z, p) - change + inertia
    return band_limited(total, float(s.t[1] - s.t[0]), float(pw["f_cut"]))[0]  # the residual's band


def _fmt(values: dict[str, float]) -> str:
    return ", ".join(f"{k}={v:.5g}" for k, v in values.items())
