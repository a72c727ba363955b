"""One diagnosis, as the loop sees it: the record and its fitting / held-out split, the nominal
system and the settings (``Case``), the nominal model once identified (``Nominal``) and what the
loop ends with (``Outcome``)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pidyn.data.sources import Record
from pidyn.discrepancy.confirm import Confirmation
from pidyn.discrepancy.effects import EFFECTS, LIBRARY, Signals
from pidyn.discrepancy.evidence import Evidence
from pidyn.discrepancy.heldout_check import HeldoutCheck
from pidyn.discrepancy.screening import Screening, screen
from pidyn.discrepancy.settings import DiagnosisSettings
from pidyn.discrepancy.step_reports import ExtensionStep, LearnedRefusal
from pidyn.simulate import simulate_response
from pidyn.systems.sdof import SDOFSystem
from pidyn.weak_form import WeakForm, measurement_noise, smooth_signals, velocity_noise

log = logging.getLogger(__name__)

IdentifyFn = Callable[[dict, Path, tuple[float, float]], tuple[dict, SDOFSystem, dict[str, float]]]


def check_diagnosable(system) -> None:
    """A named refusal for a model the diagnosis cannot extend (before any record is read)."""
    if getattr(system, "modal_coordinates", False):
        raise ValueError(
            f"system '{system.name}': the diagnosis extends force laws in physical coordinates (a single "
            "degree of freedom or a shear building's storeys), and modes have none; diagnose with "
            "system=linear, identify the modes with train.py"
        )


def split_spans(record: Record, fit_share: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """Fitting and held-out time spans: the record's own split if it has one, else a share."""
    sp = record.meta.split
    if sp:
        return sp.fit, sp.heldout
    if not 0.1 <= fit_share <= 0.95:
        raise ValueError(f"diagnosis.fit_share must lie in [0.1, 0.95], got {fit_share}")
    t0, t1 = float(record.t[0]), float(record.t[-1])
    cut = t0 + fit_share * (t1 - t0)
    return (t0, cut), (cut, t1)


@dataclass
class Case:
    """One diagnosis: the record and its split, the nominal system and its config node, the
    settings, and how a model is identified."""

    record: Record
    base: SDOFSystem
    base_node: dict
    effects: dict
    settings: DiagnosisSettings
    mass: float | None
    fit: tuple[float, float]
    held: tuple[float, float]
    run_dir: Path
    identify: IdentifyFn

    @property
    def mass_known(self) -> bool:
        return self.mass is not None

    @property
    def thresholds(self):
        return self.settings.thresholds

    @property
    def x_raw(self) -> np.ndarray:
        """The displacement: measured, or integrated from accelerometers (``accelerometers.motion_view``)."""
        if self.record.x is not None:
            return self.record.x[:, 0]
        return self.record.meta.motion.x

    @property
    def weak_f(self) -> np.ndarray:
        """The excitation the weak form pairs with ``x_raw``: high-passed alike on an accelerometer record
        (identification and output error take the record's own, unfiltered)."""
        motion = self.record.meta.motion
        return self.record.f if motion is None else motion.f

    @property
    def v_raw(self) -> np.ndarray | None:
        if self.record.v is not None:
            return self.record.v[:, 0]
        motion = self.record.meta.motion
        return None if motion is None else motion.v

    @property
    def stiff(self) -> str:
        return self.base.stiffness_name

    def mask(self, span: tuple[float, float]) -> np.ndarray:
        return (self.record.t >= span[0]) & (self.record.t <= span[1])

    def signals(self, period: float, k_nom: float, mass: float) -> tuple[Signals, WeakForm]:
        """Smoothed x, x' and the weak form, on the time scale of ``period``."""
        r = self.record
        v_raw = self.v_raw
        xs, vs = smooth_signals(r.t, self.x_raw, v_raw, period)
        return (
            Signals(
                r.t,
                xs,
                vs,
                mass,
                k_nom,
                self.stiff,
                t_fit_end=self.fit[1],
                v_noise=velocity_noise(r.t, self.x_raw, v_raw, period),
            ),
            WeakForm.for_record(r.t, period),
        )

    def screen(
        self,
        system: SDOFSystem,
        values: dict[str, float],
        s: Signals,
        weak: WeakForm,
        effects: dict | None = None,
    ) -> Screening:
        return screen(
            system,
            values,
            s,
            self.weak_f,
            self.x_raw,
            weak,
            self.fit[1],
            self.mass_known,
            effects=self.effects if effects is None else effects,
            thresholds=self.thresholds,
        )

    def free_run(self, system: SDOFSystem, values: dict[str, float], v0: float) -> np.ndarray:
        """The model from the measured initial state over the whole record."""
        return self.free_response(system, values, v0)["x"][:, 0]

    def free_response(self, system: SDOFSystem, values: dict[str, float], v0: float) -> dict[str, np.ndarray]:
        """``free_run``'s x, v and a (relative) over the whole record."""
        y0 = np.zeros(system.n_state)
        y0[0], y0[1] = float(self.x_raw[0]), v0
        return simulate_response(system, values, self.record, int(self.settings.substeps), y0)

    def noise_std(self, measured: np.ndarray, period: float) -> float:
        """The measurement noise of ``measured``: of an accelerometer, what the record says of it (the
        simulated noise level, or the sensor's RMS before the shaking), since a smoother's residual
        reads an acceleration's broadband content as noise; else the smoother's estimate."""
        meta = self.record.meta
        if self.from_accelerometers:
            level = (meta.noise_levels or {}).get("a")
            if level is not None:
                ground = self.record.f if meta.sensor_ground is None else meta.sensor_ground
                absolute = measured + np.asarray(ground, float)
                return float(level) * float(np.sqrt(np.mean(absolute**2)))
            pre = (meta.pre_event_rms or {}).get("outputs")
            if pre:
                return float(pre[0])
        return measurement_noise(self.record.t, measured, period)

    @property
    def from_accelerometers(self) -> bool:
        """The record's motion was integrated from accelerations (``accelerometers.motion_view``)."""
        return self.record.meta.accelerometers is not None


def prepare(
    record: Record,
    base: SDOFSystem,
    base_node: dict,
    settings: DiagnosisSettings,
    mass: float | None,
    run_dir: Path,
    identify: IdentifyFn,
) -> Case:
    """The settings checked against the library and the nominal system, the fit / held-out split."""
    if not isinstance(base, SDOFSystem):
        raise ValueError(f"diagnosis needs a single-degree-of-freedom nominal system, got '{base.name}'")
    effects = _screened_effects(settings, base)
    if mass is None and record.excitation == "ground":
        raise ValueError(
            "data.mass is null, but a ground-excited record cannot reveal the mass "
            "(m x'' + ... = -m ag is homogeneous in m): give the mass"
        )
    fit, held = split_spans(record, float(settings.fit_share))
    log.info(
        "diagnosing '%s' with nominal '%s': fit %.4g-%.4g s, held out %.4g-%.4g s",
        record.name,
        base.name,
        *fit,
        *held,
    )
    run_dir.mkdir(parents=True, exist_ok=True)
    return Case(record, base, base_node, effects, settings, mass, fit, held, run_dir, identify)


def _screened_effects(settings: DiagnosisSettings, base: SDOFSystem) -> dict:
    """The effects to screen: the user's list or the library, and a forced effect among them (so
    that the screening ranks it, whether or not the library screens it by default); a name outside
    the library, or a forced effect the nominal model already has, is an error before any work."""
    wanted = list(settings.effects) if settings.effects else list(LIBRARY)
    forced = settings.force_effect
    if forced and forced not in wanted:
        wanted.append(forced)
    unknown = set(wanted) - set(EFFECTS)
    if unknown:
        what = "force_effect" if unknown == {forced} else "effects"
        raise ValueError(
            f"diagnosis.{what}: unknown effect(s) {sorted(unknown)}; the library has {sorted(EFFECTS)}"
        )
    already = {t.name for t in base.terms} & set(wanted)
    if forced in already:
        raise ValueError(f"diagnosis.force_effect={forced!r}: the nominal model already has it")
    if already:  # an effect the nominal model already has cannot be what it misses
        log.info("not screening %s: already in the nominal model", sorted(already))
    return {n: EFFECTS[n] for n in wanted if n not in already}


@dataclass
class Nominal:
    node: dict
    system: SDOFSystem
    values: dict[str, float]
    metrics: dict
    polish_note: str | None
    s: Signals
    weak: WeakForm
    period: float


@dataclass
class Extension:
    """A single degree of freedom's extensions so far: the last extended model (its system, values
    and identification's metrics), the causes added and each step's record; the polish's note, a
    refused learned force, the learned force's training, and names that did not earn their place."""

    system: Any = None
    values: dict[str, float] | None = None
    metrics: dict | None = None
    causes: list[str] = field(default_factory=list)
    steps: list[ExtensionStep] = field(default_factory=list)
    note: str | None = None
    refused: LearnedRefusal | None = None
    learned_fit: dict | None = None
    unearned: dict | None = None


@dataclass
class Outcome:
    """Everything the summary and the figures are made of."""

    nominal: Nominal
    screening: Screening
    check: HeldoutCheck
    change_row: Evidence | None
    extension: Extension
    causes: list[str]
    cause: str | None
    forced: bool
    confirmation: Confirmation | None
    pointwise: dict
    x_nom: np.ndarray
    x_ext: np.ndarray | None
    sims: dict = field(
        default_factory=dict
    )  # nominal / extended: x, v, a over the record (accelerometer records)
    modal: list[dict] | None = None  # the nominal model's modes with 95 % intervals
    running: dict | None = None  # period and damping window by window (accelerometer records)
