"""The diagnosis task: what does the nominal model get wrong, why, and what does fixing it gain?

1. identify the nominal model on the fitting part (PIDynNet, then optionally an output-error
   polish);
2. compute the force it cannot explain (figures: over time, against x and x', spectrum);
3. screen the effect library against it (``pidyn.discrepancy.screening``) and name the cause,
   or ``none``; an effect the weak-form screening leans to without deciding is fitted by output
   error and named when the simulated response decides for it (``pidyn.discrepancy.confirm``);
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
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import hydra
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf, open_dict

from pidyn.baselines.least_squares import output_error
from pidyn.data.sources import Record
from pidyn.discrepancy.changes import heldout_check, locate_change, running_estimate
from pidyn.discrepancy.confirm import Confirmation, confirm, undecided
from pidyn.discrepancy.effects import EFFECTS, Signals
from pidyn.discrepancy.learned_fit import fit_learned_force
from pidyn.discrepancy.report import (plot_learned_force, plot_ranking, plot_residual, plot_response,
                                     plot_running_estimate, write_report)
from pidyn.discrepancy.residual import band_limited, dominant_period, unexplained_force
from pidyn.discrepancy.screening import EXCLUSIVE, Thresholds, screen, weak_system
from pidyn.discrepancy.weak_form import WeakForm, measurement_noise, smooth_signals, velocity_noise
from pidyn.reporting import nrmse, write_json
from pidyn.systems.sdof import SDOFSystem
from pidyn.systems.terms import LearnedForce
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


@dataclass
class _Case:
    """One diagnosis: the record and its split, the nominal system, the settings."""

    cfg: DictConfig
    record: Record
    base: SDOFSystem
    effects: dict
    thresholds: Thresholds
    mass_known: bool
    fit: tuple[float, float]
    held: tuple[float, float]
    run_dir: Path

    @property
    def dcfg(self) -> DictConfig:
        return self.cfg.diagnosis

    @property
    def x_raw(self) -> np.ndarray:
        return self.record.x[:, 0]

    @property
    def stiff(self) -> str:
        return _stiffness_name(self.base)

    def mask(self, span: tuple[float, float]) -> np.ndarray:
        return (self.record.t >= span[0]) & (self.record.t <= span[1])

    def signals(self, period: float, k_nom: float, mass: float) -> tuple[Signals, WeakForm]:
        """Smoothed x, x' and the weak form, on the time scale of ``period``."""
        r = self.record
        v_raw = None if r.v is None else r.v[:, 0]
        xs, vs = smooth_signals(r.t, self.x_raw, v_raw, period)
        return (Signals(r.t, xs, vs, mass, k_nom, self.stiff, t_fit_end=self.fit[1],
                        v_noise=velocity_noise(r.t, self.x_raw, v_raw, period)),
                WeakForm.for_record(r.t, period))

    def screen(self, system: SDOFSystem, values: dict[str, float], s: Signals, weak: WeakForm,
               effects: dict | None = None):
        return screen(system, values, s, self.record.f, self.x_raw, weak, self.fit[1], self.mass_known,
                      effects=self.effects if effects is None else effects, thresholds=self.thresholds)

    def free_run(self, system: SDOFSystem, values: dict[str, float], v0: float) -> np.ndarray:
        """The model from the measured initial state over the whole record."""
        return simulate_identified(system, values, self.record, x0=float(self.x_raw[0]), v0=v0,
                                   substeps=int(self.dcfg.substeps))[:, 0]


@dataclass
class _Nominal:
    node: dict
    system: SDOFSystem
    values: dict[str, float]
    metrics: dict
    polish_note: str | None
    s: Signals
    weak: WeakForm
    period: float


def diagnose(cfg: DictConfig, record: Record | None = None) -> dict[str, Any]:
    """What the nominal model ``cfg.system`` misses on ``record`` (default: built from
    ``cfg.data``); writes diagnosis.json, report.md and figures to the run folder."""
    t_wall = time.perf_counter()
    case = _prepare(cfg, record)
    values0, period = _starting_point(case)
    nom = _identify_nominal(case, values0, period)
    # 2-3. what the nominal model cannot explain, and which effect explains it
    sc = case.screen(nom.system, nom.values, nom.s, nom.weak)
    pointwise = unexplained_force(nom.system, nom.values, case.record.t, case.x_raw, case.record.f, nom.period)
    forced = case.dcfg.get("force_effect")
    log.info("screening: %s", ", ".join(f"{r['effect']} {r['score']:.1f}" for r in sc.ranking[:4]))
    # 3b. does the nominal model hold on the held-out part? if not, when did the structure change?
    x_nom = case.free_run(nom.system, nom.values, float(nom.s.v[0]))
    check, change_row = _check_heldout(case, nom, sc, x_nom, bool(forced))
    cause = change_row["effect"] if change_row is not None else (forced or sc.cause)
    confirmation = None
    if cause is None and not forced and sc.verdict == "none":
        # 3c. an effect the weak form leans towards without deciding: the simulated response decides
        confirmation = _confirm(case.cfg, case.record, nom.system, nom.values, nom.node, sc, nom.s, 1,
                                case.mass_known, case.fit, case.held, case.thresholds)
        if confirmation.row is not None:
            cause = confirmation.row["effect"]
    # 4. extended model(s): extend, screen again, until nothing more passes the evidence
    #    thresholds or diagnosis.max_effects is reached
    if cause is None and bool(case.dcfg.get("learn_unexplained", True)) and not forced \
            and (sc.verdict == "unexplained" or check.failed):
        cause = LEARNED  # structured, but nothing in the library explains it: learn the force
    row = None if cause is None else (_learned_row(sc) if cause == LEARNED else
                                      change_row or (confirmation.row if confirmation and confirmation.row else
                                                     next(r for r in sc.ranking if r["effect"] == cause)))
    ext = _extend_until_explained(cfg, case.record, nom.node, nom.values, cause, row, nom.s, nom.weak, case.x_raw,
                                  case.fit, case.held, case.effects, case.thresholds, case.mass_known, bool(forced))
    causes = ext["causes"] if case.dcfg.extend else ([] if cause is None else [cause])
    # 5. held-out gain
    x_ext = case.free_run(ext["system"], ext["values"], float(nom.s.v[0])) if ext["system"] is not None else None
    diagnosis = _summary(case, nom, sc, check, change_row, ext, causes, cause, bool(forced), x_nom, x_ext)
    diagnosis["confirmation"] = None if confirmation is None else confirmation.tested
    diagnosis["learned_force_refused"] = ext.get("refused")
    diagnosis["wall_seconds"] = time.perf_counter() - t_wall
    write_json(case.run_dir / "diagnosis.json", diagnosis)
    _write_figures(case, nom, sc, diagnosis, change_row, ext, pointwise, x_nom, x_ext)
    log.info("verdict: %s%s; held-out NRMSE nominal %.4g%s", diagnosis["verdict"],
             f" ({diagnosis['cause']})" if diagnosis["cause"] else "", diagnosis["gain"]["nominal"],
             "" if diagnosis["gain"]["extended"] is None else f", extended {diagnosis['gain']['extended']:.4g}")
    log.info("run folder %s (%.0f s)", case.run_dir, diagnosis["wall_seconds"])
    return diagnosis


def _prepare(cfg: DictConfig, record: Record | None) -> _Case:
    """The settings checked, the nominal system, the record and its fit / held-out split."""
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
    if mass is None and record.excitation == "ground":
        raise ValueError("data.mass is null, but a ground-excited record cannot reveal the mass "
                         "(m x'' + ... = -m ag is homogeneous in m): give the mass")
    fit, held = split_spans(record, float(dcfg.fit_share))
    log.info("diagnosing '%s' with nominal '%s': fit %.4g-%.4g s, held out %.4g-%.4g s",
             record.name, base.name, *fit, *held)
    return _Case(cfg, record, base, effects, thresholds, mass is not None, fit, held, run_dir)


def _starting_point(case: _Case) -> tuple[dict[str, float], float]:
    """A data-driven start for the nominal parameters (weak-form least squares, no effect) and
    the natural period, refined once from the start's own stiffness."""
    period = dominant_period(case.record.t[case.mask(case.fit)], case.x_raw[case.mask(case.fit)])
    values0 = {s.name: s.init for s in case.base.param_specs()}
    if case.mass_known:
        values0["m"] = float(case.cfg.data.get("mass", 1.0))
    s, weak = case.signals(period, values0[case.stiff], values0.get("m", 1.0))
    values0.update(case.screen(case.base, values0, s, weak, effects={}).nominal_params)
    if values0.get(case.stiff, 0) > 0 and values0.get("m", 0) > 0:
        period = 2 * np.pi * np.sqrt(values0["m"] / values0[case.stiff])
        s, weak = case.signals(period, values0[case.stiff], values0.get("m", 1.0))
        values0.update(case.screen(case.base, values0, s, weak, effects={}).nominal_params)
    log.info("weak-form starting point: %s (natural period %.4g s)", _fmt(values0), period)
    return values0, period


def _identify_nominal(case: _Case, values0: dict[str, float], period: float) -> _Nominal:
    """1. The nominal model on the fitting part: PIDynNet, then the output-error polish."""
    cfg, record = case.cfg, case.record
    node = _system_node(cfg.system, {k: v for k, v in values0.items() if v > 0},
                        values0["m"] if "m" in values0 else 1.0, not case.mass_known)
    if record.excitation != OmegaConf.select(cfg, "system.excitation", default=record.excitation):
        node["excitation"] = record.excitation
    metrics, obj = identify(_sub_cfg(cfg, node, case.run_dir / "nominal", case.fit), record)
    system: SDOFSystem = obj["system"]
    values = obj["module"].net.params.as_floats()
    polish_note = None
    if case.dcfg.polish:
        values, polish_note = _polish(record, system, values, case.dcfg, case.fit)
    s, weak = case.signals(period, values[case.stiff], values0.get("m", 1.0))
    s.mass = values["m"]
    return _Nominal(node, system, values, metrics, polish_note, s, weak, period)


def _check_heldout(case: _Case, nom: _Nominal, sc, x_nom: np.ndarray, forced: bool) -> tuple[Any, dict | None]:
    """The held-out failure check, and where the structure changed when the data say it did
    (a located change moves ``case.fit`` / ``case.held`` to the change point)."""
    check = heldout_check(case.x_raw, x_nom, case.mask(case.fit), case.mask(case.held),
                          measurement_noise(case.record.t, case.x_raw, nom.period),
                          threshold=float(case.dcfg.changes.heldout_ratio))
    log.info("%s", check.sentence())
    time_effects = {n: p_ for n, p_ in {"stiffness_loss": case.stiff, "damping_change": "c"}.items()
                    if n in case.effects and p_ in nom.values}
    if forced or not time_effects or not ((check.failed and sc.cause is None) or sc.cause in time_effects):
        return check, None
    change, case.fit, case.held = _locate_change(
        nom.system, nom.values, nom.s, case.record, case.x_raw, nom.weak, case.fit, case.held, case.mass_known,
        {n: p_ for n, p_ in time_effects.items() if sc.cause in (None, n)}, case.thresholds,
        bool(check.failed and sc.cause is None))
    if change is None:
        return check, None
    log.info("%s", change.sentence())
    return check, {"effect": change.effect, "parameters": change.effect_parameters(), "nominal_refit": {},
                   "score": -change.delta_bic, "change": change}


def _summary(case: _Case, nom: _Nominal, sc, check, change_row: dict | None, ext: dict, causes: list[str],
             cause: str | None, forced: bool, x_nom: np.ndarray, x_ext: np.ndarray | None) -> dict[str, Any]:
    """The content of diagnosis.json: verdict, causes, evidence, parameters, held-out gain."""
    record, held_mask = case.record, case.mask(case.held)
    gain = {"metric": "heldout_nrmse_x", "nominal": nrmse(x_nom[held_mask], case.x_raw[held_mask]),
            "extended": None if x_ext is None else nrmse(x_ext[held_mask], case.x_raw[held_mask])}
    if record.clean is not None:
        xc = record.clean.x[:, 0]
        gain["nominal_vs_clean"] = nrmse(x_nom[held_mask], xc[held_mask])
        gain["extended_vs_clean"] = None if x_ext is None else nrmse(x_ext[held_mask], xc[held_mask])
    learned = LEARNED in causes
    causes = [c for c in causes if c != LEARNED]
    ext_system, ext_values, ext_metrics = ext["system"], ext["values"], ext["metrics"]
    effect_params: dict[str, Any] = {}
    if ext_values is not None and ext_system is not None:
        nominal_names = {sp.name for sp in nom.system.param_specs()}
        effect_params = {k: v for k, v in ext_values.items() if k not in nominal_names}
    if change_row is not None:
        ch = change_row["change"]
        effect_params["t_change"] = effect_params.get("t_d", ch.t_change)
        effect_params["t_change_ci95"] = list(ch.ci95)
    verdict = ("discrepancy" if causes or (cause is not None and cause != LEARNED) else
               "unexplained" if learned or check.failed or sc.verdict == "unexplained" else "none")
    truth = dict(record.meta.get("hidden_params") or {}) if "hidden_effect" in record.meta else None
    return {
        "nominal": nom.system.describe(nom.values),
        "verdict": verdict,
        "cause": causes[0] if causes else (None if cause == LEARNED else cause),
        "causes": causes,
        "steps": ext["steps"],
        "learned_force": learned,
        "structure": {k: v for k, v in sc.structure.items()},
        "heldout_check": check.__dict__,
        "change": None if change_row is None else change_row["change"].to_dict(),
        "forced": forced,
        "ranking": sc.ranking,
        "extended": ext_system.describe(ext_values) if ext_system is not None else None,
        "parameters": effect_params,
        "nominal_parameters": nom.values,
        "extended_parameters": ext_values,
        "gain": gain,
        "split": {"fit": list(case.fit), "heldout": list(case.held)},
        "record": record.name,
        "noise": (record.meta or {}).get("noise"),
        "natural_period": nom.period,
        "thresholds": OmegaConf.to_container(case.dcfg.thresholds, resolve=True),
        "polish": {"nominal": nom.polish_note, "extended": ext["note"]},
        "learned_fit": ext.get("learned_fit"),
        "pidynnet": {"nominal_errors_pct": nom.metrics.get("error_pct"),
                     "extended_errors_pct": None if ext_metrics is None else ext_metrics.get("error_pct")},
        "hidden": None if truth is None else {"effect": record.meta.get("hidden_effect"), "parameters": truth},
    }


def _write_figures(case: _Case, nom: _Nominal, sc, d: dict, change_row: dict | None, ext: dict, pointwise: dict,
                   x_nom: np.ndarray, x_ext: np.ndarray | None) -> None:
    """The figures and report.md of the run folder."""
    record, fit, held, period, cause = case.record, case.fit, case.held, nom.period, d["cause"]
    fig = case.run_dir / "figures"
    fig.mkdir(exist_ok=True)
    units = (record.meta or {}).get("units", {})
    plot_response(fig / "simulation_vs_measured.png", record.t, case.x_raw, x_nom, x_ext, fit, held,
                  units.get("x", "m"), period)
    explained = None
    if cause is not None:
        explained = _explained_force(nom.system, nom.values,
                                     change_row or next(r for r in sc.ranking if r["effect"] == cause), nom.s,
                                     pointwise)
    plot_residual(fig / "residual.png", record.t, pointwise["r"], pointwise["x"], pointwise["v"], fit, cause,
                  explained, units, period)
    plot_ranking(fig / "ranking.png", sc.ranking, case.thresholds.min_delta_bic)
    names, A0, y = weak_system(nom.system, nom.values, nom.s, record.f, case.x_raw, nom.weak, case.mass_known)
    running = running_estimate(names, A0, y, nom.weak.centers,
                               max(4 * period, 3 * nom.weak.dt * (2 * nom.weak.half + 1)))
    plot_running_estimate(fig / "running_estimate.png", running, nom.values, fit, held,
                          None if change_row is None else change_row["change"])
    if d["learned_force"] and ext["system"] is not None and ext["system"].n_latent == 0:
        _plot_learned(fig / "learned_force.png", record.t, nom.system, nom.values, ext["system"], ext["values"],
                      pointwise, units)
    write_report(case.run_dir / "report.md", d, [p.name for p in sorted(fig.glob("*.png"))])


EXTENSION = "pidyn.discrepancy.extend.extended_system"


def _extend_until_explained(cfg: DictConfig, record: Record, nominal_node: dict, nominal_values: dict[str, float],
                            cause: str | None, row: dict | None, s: Signals, weak: WeakForm, x_raw: np.ndarray,
                            fit: tuple[float, float], held: tuple[float, float], effects: dict,
                            thresholds: Thresholds, mass_known: bool, forced: bool) -> dict[str, Any]:
    """Extend the model with ``cause``, identify it (PIDynNet, polish), screen the extended
    model against the effects not yet in it, and repeat while one passes the thresholds, up to
    ``diagnosis.max_effects``. Each step's evidence is kept; the last model carries every
    named effect. Step k's run is in ``extended/`` (k = 1) or ``extended_<k>/``."""
    dcfg = cfg.diagnosis
    run_dir = Path(cfg.paths.output_dir)
    out: dict[str, Any] = {"system": None, "values": None, "metrics": None, "causes": [], "steps": [], "note": None,
                           "refused": None, "learned_fit": None}
    node, values = nominal_node, nominal_values
    limit = 1 if forced else int(dcfg.get("max_effects", 3))
    while cause is not None and row is not None and dcfg.extend:
        if row.get("score") is not None and not np.isfinite(row["score"]):
            raise ValueError(f"effect '{cause}' has no physical fit to this record ({row.get('note')})")
        k = len(out["causes"]) + 1
        if cause == LEARNED:  # start the network at the force the current model cannot explain
            row = {**row, "parameters": {"init_from": str(_save_unexplained(run_dir / f"unexplained_{k}.npz", record,
                                                                          _current_system(node), values, x_raw,
                                                                          fit))}}
        ext_node = _extension_node(node, values, cause, row, s, k, mass_known)
        folder = run_dir / ("extended" if k == 1 else f"extended_{k}")
        metrics, obj = identify(_sub_cfg(cfg, ext_node, folder, fit), record)
        system: SDOFSystem = obj["system"]
        ext_values = obj["module"].net.params.as_floats()
        if dcfg.polish:  # a held change time is refined here, from where the search put it
            ext_values, out["note"] = _polish(record, _current_system(_release_held(ext_node)), ext_values, dcfg, fit)
        if cause == LEARNED and (dcfg.get("learned") or {}).get("output_error", True):
            ext_values, out["learned_fit"] = _train_learned(record, system, ext_values, s, fit, dcfg, folder)
        if cause == LEARNED:
            out["refused"], errors = _refuse_learned(record, _current_system(node), values, system, ext_values,
                                                     x_raw, float(s.v[0]), held, int(dcfg.substeps), folder)
            if out["refused"] is not None:  # a network that fits the fitting part but predicts worse
                break
        out["causes"].append(cause)
        out["steps"].append({"step": k, "effect": cause, "folder": folder.name, "equation": system.describe(ext_values),
                             "evidence": {**{key: row.get(key) for key in _ROW_EVIDENCE},
                                          **({"heldout_nrmse": errors} if cause == LEARNED else {})}})
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
        cause, row = _next_cause(cfg, record, system, ext_values, node, remaining, out, s, weak, x_raw, fit, held,
                                 thresholds, mass_known)
        if cause == LEARNED and LEARNED in out["causes"]:
            break
    return out


def _next_cause(cfg: DictConfig, record: Record, system: SDOFSystem, values: dict[str, float], node: dict,
                remaining: dict, out: dict[str, Any], s: Signals, weak: WeakForm, x_raw: np.ndarray,
                fit: tuple[float, float], held: tuple[float, float], thresholds: Thresholds,
                mass_known: bool) -> tuple[str | None, dict | None]:
    """Screen the model just extended against the effects not yet in it; what the weak form
    leaves undecided goes to the output-error check, and a structured remainder no library
    effect explains to the learned force. The evidence lands on the last step of ``out``."""
    k = len(out["causes"])
    sc = screen(system, values, s, record.f, x_raw, weak, fit[1], mass_known, remaining, thresholds)
    step = out["steps"][-1]
    step["next_ranking"] = [{k_: r.get(k_) for k_ in _STEP_EVIDENCE if k_ in r} for r in sc.ranking]
    step["next_structure"] = dict(sc.structure)
    step["next_verdict"] = sc.verdict
    log.info("screening the extended model: %s", ", ".join(f"{r['effect']} {r['score']:.1f}"
                                                           for r in sc.ranking[:4] if r.get("score") is not None))
    if sc.cause is not None:
        return sc.cause, next(r for r in sc.ranking if r["effect"] == sc.cause)
    if sc.verdict == "none":  # the simulated response decides what the weak form leans to
        confirmation = _confirm(cfg, record, system, values, node, sc, s, k + 1, mass_known, fit, held, thresholds)
        step["next_confirmation"] = confirmation.tested
        if confirmation.row is not None:
            return confirmation.row["effect"], confirmation.row
    if sc.verdict == "unexplained" and LEARNED not in out["causes"] and cfg.diagnosis.get("learn_unexplained", True):
        return LEARNED, _learned_row(sc)  # what remains is structured but no library effect: learn it
    return None, None


def _confirm(cfg: DictConfig, record: Record, system: SDOFSystem, values: dict[str, float], node: dict, sc,
             s: Signals, k: int, mass_known: bool, fit: tuple[float, float], held: tuple[float, float],
             thresholds: Thresholds) -> Confirmation:
    """The output-error check of the effects screening ``sc`` leaves undecided
    (``pidyn.discrepancy.confirm``); ``diagnosis.confirm.max_candidates`` = 0 turns it off."""
    dcfg = cfg.diagnosis
    ccfg = dcfg.get("confirm") or {}
    candidates = undecided(sc.ranking, thresholds, int(ccfg.get("max_candidates", 3)))
    if not candidates:
        return Confirmation()
    node = _release_held(node)  # as in the polish: a located change time is refined with the rest
    build = lambda row: _current_system(_extension_node(node, values, row["effect"], row, s, k, mass_known))  # noqa: E731
    return confirm(record, _current_system(node), values, candidates, build, fit, held, thresholds,
                   substeps=int(dcfg.substeps),
                   max_nfev=int(dcfg.polish_max_nfev), polish_seconds=dcfg.polish_seconds)


LEARNED = "learned_force"
#: what each step keeps of the row that named its effect
_ROW_EVIDENCE = ("score", "delta_bic", "explained", "cv_gain", "heldout_gain", "force_share", "source")
#: what each step keeps of the next screening's rows: the evidence behind the next name
_STEP_EVIDENCE = ("effect", "score", "delta_bic", "explained", "cv_gain", "heldout_gain", "force_share", "passes",
                  "persists", "heldout_miss", "heldout_small", "note", "parameters", "source")


def _extension_node(node: dict, values: dict[str, float], cause: str, row: dict, s: Signals, k: int,
                    mass_known: bool) -> dict:
    """The config node of step ``k``'s model: the current model (its values; at the first step
    the screening's refit of the nominal parameters) extended with ``cause`` started at the
    screening's estimate."""
    refit = {n: v for n, v in row["nominal_refit"].items() if v > 0} if k == 1 else {}
    inner = _node_with_values(node, {**values, **refit})
    if k == 1:
        inner = _system_node(OmegaConf.create(inner), refit, refit.get("m", values["m"]), not mass_known)
    node = {"_target_": EXTENSION, "nominal": inner, "effect": cause,
            "effect_params": {n: (v if isinstance(v, str) else float(v)) for n, v in row["parameters"].items()},
            "context": s.context()}
    if row.get("change") is not None:  # located over the record, with an interval: held (see extended_system)
        node["held"] = ["t_d"]
    return node


def _release_held(node: dict) -> dict:
    """A copy of a system node with every held effect parameter free again (the polish and the
    output-error check refine a located change time from its located value)."""
    node = copy.deepcopy(OmegaConf.to_container(node, resolve=True) if isinstance(node, DictConfig) else node)
    if node.get("_target_") == EXTENSION:
        node.pop("held", None)
        node["nominal"] = _release_held(node["nominal"])
    return node


def _current_system(node: dict) -> SDOFSystem:
    return hydra.utils.instantiate(OmegaConf.create(node))


def _learned_predicts(record: Record, before: SDOFSystem, before_values: dict[str, float], after: SDOFSystem,
                      after_values: dict[str, float], x_raw: np.ndarray, v0: float, held: tuple[float, float],
                      substeps: int) -> tuple[bool, dict[str, float]]:
    """Does the model with a learned force predict the held-out part better than the model it
    extends? A network trained on the fitting part can fit it and still extrapolate wrongly
    (a trilinear spring reached further in the held-out part): kept only if it predicts better.
    The held-out part decides here, as it does for the screening's held-out rules."""
    mask = (record.t >= held[0]) & (record.t <= held[1])
    errors = {}
    for key, system, vals in (("without", before, before_values), ("with", after, after_values)):
        x = simulate_identified(system, vals, record, x0=float(x_raw[0]), v0=v0, substeps=substeps)[:, 0]
        errors[key] = nrmse(x[mask], x_raw[mask]) if np.all(np.isfinite(x)) else float("inf")
    return bool(mask.any() and errors["with"] < errors["without"]), errors


def _train_learned(record: Record, system: SDOFSystem, values: dict[str, float], s: Signals,
                   fit: tuple[float, float], dcfg: DictConfig, folder: Path) -> tuple[dict[str, float], dict | None]:
    """The learned force (weights set in place) and the physical parameters trained further on
    the simulated response of the fitting part (``pidyn.discrepancy.learned_fit``); the weights
    are written to ``folder/learned_force.pt`` (the PIDynNet checkpoint there holds the ones
    before this training)."""
    lcfg = dcfg.get("learned") or {}
    period = 2 * np.pi * np.sqrt(values["m"] / max(values.get(s.stiffness, s.k_nominal), 1e-300))
    res = fit_learned_force(system, values, record, fit, period, smoothed=(s.x, s.v),
                            periods_per_segment=float(lcfg.get("periods_per_segment", 3.0)),
                            max_evaluations=int(lcfg.get("max_evaluations", 60)))
    if res is None:
        return values, None
    nets = [t.net.state_dict() for t in system.terms if isinstance(t, LearnedForce)]
    torch.save({"values": res.values, "networks": nets}, folder / "learned_force.pt")
    return res.values, {"note": res.note, "loss_before": res.loss_before, "loss_after": res.loss_after,
                        "evaluations": res.evaluations, "segments": res.segments,
                        "segment_seconds": res.segment_seconds, "seconds": res.seconds,
                        "file": f"{folder.name}/learned_force.pt"}


def _refuse_learned(record: Record, before: SDOFSystem, before_values: dict[str, float], after: SDOFSystem,
                    after_values: dict[str, float], x_raw: np.ndarray, v0: float, held: tuple[float, float],
                    substeps: int, folder: Path) -> tuple[dict | None, dict[str, float]]:
    """Why the learned force of the run in ``folder`` is not kept (None: it is), and both
    held-out errors."""
    kept, errors = _learned_predicts(record, before, before_values, after, after_values, x_raw, v0, held, substeps)
    if kept:
        return None, errors
    note = (f"the learned force predicts the held-out part worse (NRMSE {errors['with']:.3g}) than the model "
            f"it extends ({errors['without']:.3g}): not kept")
    log.info("%s: %s", folder.name, note)
    return {"effect": LEARNED, "folder": folder.name, "heldout_nrmse": errors, "note": note}, errors


def _save_unexplained(path: Path, record: Record, system: SDOFSystem, values: dict[str, float], x_raw: np.ndarray,
                      fit: tuple[float, float]) -> Path:
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
    runs on the fitting part (the screening already named the time-varying effect).

    A step that fits the rows after its fitting part worse than no step (held-out gain below
    ``th.min_step_heldout_gain``) does not persist: a stiffness lower only in the strong motion
    depends on the amplitude (softening), it is no damage. Nothing is named then, the split stays
    where it was, and the screening's rule for a step in time holds here too."""
    names, A0, y = weak_system(nominal, values, s, record.f, x_raw, weak, mass_known)
    w = 2 * weak.half + 1
    t_first, t_last = weak.t[weak.starts], weak.t[weak.starts + w - 1]

    def search(end: float):
        rows = t_last <= end + 1e-9
        n_eff = max(rows.sum() / weak.rows_per_independent, 2.0)
        return locate_change(names, A0, y, t_first, t_last, rows, s.x, s.v, s.t, weak, n_eff, candidates, values,
                             heldout=t_first >= end - 1e-9)

    fit0, held0 = fit, held
    change = search(float(record.t[-1]) if whole_record else fit[1])
    if change is not None and not EFFECTS[change.effect].admissible(change.effect_parameters(), values):
        log.info("the best step in time, %s, is not one the library can name (outside its range)", change.sentence())
        return None, fit, held
    if change is not None and _stiffening(change):
        return None, fit, held
    if change is None or change.delta_bic > -th.min_delta_bic or change.explained < th.min_cv_gain:
        log.info("no step in %s explains the residual%s", " or ".join(sorted(set(candidates.values()))),
                 "" if change is None else f" (best: {change.sentence()}, dBIC {change.delta_bic:.1f})")
        return None, fit, held
    if whole_record:
        cut = max(fit[1], change.t_change + 0.5 * (float(record.t[-1]) - change.t_change))
        if cut > fit[1]:
            log.info("the change lies at %.4g s, late in or beyond the fitting part: fitting now %.4g-%.4g s, "
                     "held out %.4g-%.4g s",
                     change.t_change, fit[0], cut, cut, held[1])
            fit, held = (fit[0], cut), (cut, held[1])
        again = search(fit[1])
        if again is not None and _stiffening(again):
            return None, fit0, held0
        change = again if again is not None else change
        if not EFFECTS[change.effect].admissible(change.effect_parameters(), values):
            log.info("re-estimated on the new fitting part, %s is outside the library's range; none is named",
                     change.sentence())
            return None, fit0, held0
    if not th.step_persists(change.heldout_gain):
        log.info("%s, but the step does not persist: fitted up to %.4g s it fits the rest worse than no step "
                 "(held-out gain %.2f); a change in time lasts, a stiffness or damping that differs only in the "
                 "strong motion depends on the amplitude; none is named", change.sentence(), fit[1], change.heldout_gain)
        return None, fit0, held0
    return change, fit, held


def _stiffening(change) -> bool:
    """A stiffness that rises at some time is not a stiffness loss: under an earthquake it is
    the mark of a stiffness that depends on the amplitude (softening in the strong motion,
    stiffer again as the motion dies down), which no change in time explains. Say so, name
    nothing."""
    if change.effect != "stiffness_loss" or change.fraction <= 0:
        return False
    log.info("the best step in time is a stiffness rise (%s): that is an amplitude-dependent stiffness, not damage; "
             "no change in time is named", change.sentence())
    return True


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
