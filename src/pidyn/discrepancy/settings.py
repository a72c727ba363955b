"""The diagnosis's settings as typed dataclasses: the one source of their defaults. Hydra composes
them as the schema of ``diagnose.yaml``'s ``diagnosis`` node (``pidyn.schemas``), which holds
overrides only."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from pidyn.discrepancy.screening_rules import Thresholds


@dataclass
class LearnedSettings:
    """A learned force f(x, x'): trained further on the simulated response of the fitting part."""

    output_error: bool = True
    periods_per_segment: float = 3.0
    max_evaluations: int = 60
    #: a building with no structured storey: the learned force is tried in this many storeys, those
    #: whose library candidates together explain most of the misfit (``storey_ranking.storey_order``)
    storeys: int = 2
    #: ... the first of them is trained on unless another's brief fit ends lower by this share of
    #: the first's fit ratio (loss after / before)
    choice_margin: float = 0.1


@dataclass
class ConfirmSettings:
    """The output-error check of effects the weak form leans to without deciding (0: off)."""

    max_candidates: int = 3
    #: a building whose model fails the fit test (``fit_test``) with nothing named: this many
    #: (effect, storey) pairs are fitted by output error, in the order of the score test on the
    #: simulated floor accelerations (``storey_ranking``), whatever the weak form scored them
    misfit_candidates: int = 3
    #: and such an effect is named only when it removes this share of the fitting part's squared
    #: excess over the noise (summed over the floors)
    misfit_share: float = 0.5
    #: ... and the search stops at one that removes this share (the candidates come best first)
    misfit_done: float = 0.9
    #: after a named effect, a building that still fails the fit test: the score test's candidates
    #: in the other storeys are fitted when the best removes this share of the squared residual
    #: (linearised); 0 turns the search after a named effect off
    after_named_share: float = 0.4


@dataclass
class FitTestSettings:
    """Whether the model fits its fitting part down to the sensors' noise (``pidyn.discrepancy.fit_test``)."""

    #: a channel fails when its residual RMS is this many times its noise floor (clean buildings
    #: with noise stay at or below 1.18 times, experiments/results/fit_test_calibration.md; at 2.0
    #: a damping change that left floor 1 at 1.90 times went unsearched)
    rms_ratio: float = 1.5
    #: and exceeds it by this share of the channel's signal (NRMSE above the noise)
    min_excess: float = 0.02


@dataclass
class ChangeSettings:
    """The held-out failure check that starts the search for a change in time."""

    #: the held-out test's level: the nominal model fails when a correct model would leave the
    #: held-out part's simulation error with a smaller probability than this (see HeldoutCheck)
    heldout_level: float = 0.001


@dataclass
class DiagnosisSettings:
    """What the diagnosis does and when it names an effect."""

    fit_share: float = 0.65  # fitting share of the record when the data carry no split of their own
    effects: list[str] | None = None  # a subset of the library to screen (None: all)
    force_effect: str | None = None  # extend with this effect whatever the screening says
    extend: bool = True  # extend the model with what the screening names (False: screen only)
    #: a structured residual no library effect explains: add a learned force f(x, x')
    learn_unexplained: bool = True
    max_effects: int = 3  # extend, screen again, extend ... at most this many effects
    #: a building: a storey effect is named only when the extended model predicts the held-out
    #: floor accelerations better than the model it extends by this share (NRMSE)
    storey_min_gain: float = 0.01
    #: a building: a named effect's size (its key parameter) must be determined, its standard
    #: deviation at most this share of it (two standard deviations from zero)
    storey_max_rel_std: float = 0.5
    #: PIDynNet starts from the weak form's estimates, not its own first-window solve
    ls_init: str | None = "none"
    polish: bool = True  # output-error least squares after each PIDynNet identification
    polish_seconds: float | None = None  # length of the fitting part the polish uses (None: all)
    polish_max_nfev: int = 30
    #: every output-error fit of the diagnosis stops when a step lowers its cost by less than this
    #: share: a model choice by BIC over ~1000 independent samples moves by less than 0.01 then,
    #: where a fit of a located change crawled on at 1e-7 a step through its whole budget (66 s)
    polish_tol: float = 1e-6
    substeps: int = 4  # RK4 substeps per sample in simulations
    learned: LearnedSettings = field(default_factory=LearnedSettings)
    confirm: ConfirmSettings = field(default_factory=ConfirmSettings)
    changes: ChangeSettings = field(default_factory=ChangeSettings)
    fit_test: FitTestSettings = field(default_factory=FitTestSettings)
    thresholds: Thresholds = field(default_factory=Thresholds)

    def __post_init__(self) -> None:
        if not 0.1 <= float(self.fit_share) <= 0.95:
            raise ValueError(f"diagnosis.fit_share must lie in [0.1, 0.95], got {self.fit_share}")
        if int(self.max_effects) < 1:
            raise ValueError(f"diagnosis.max_effects must be >= 1, got {self.max_effects}")
        if not 0.0 <= float(self.confirm.after_named_share) <= 1.0:
            raise ValueError(
                f"diagnosis.confirm.after_named_share must lie in [0, 1], got {self.confirm.after_named_share}"
            )
        if float(self.storey_max_rel_std) <= 0.0:
            raise ValueError(f"diagnosis.storey_max_rel_std must be > 0, got {self.storey_max_rel_std}")
        if not 0.0 <= float(self.learned.choice_margin) < 1.0:
            raise ValueError(
                f"diagnosis.learned.choice_margin must lie in [0, 1), got {self.learned.choice_margin}"
            )

    @classmethod
    def from_mapping(cls, node: Mapping[str, Any] | None) -> DiagnosisSettings:
        """From the config's ``diagnosis`` node (a plain mapping); an unknown key fails, naming the known ones."""
        node = dict(node or {})
        nested = {
            "learned": LearnedSettings,
            "confirm": ConfirmSettings,
            "changes": ChangeSettings,
            "fit_test": FitTestSettings,
            "thresholds": Thresholds,
        }
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = set(node) - known
        if unknown:
            raise ValueError(f"diagnosis: unknown setting(s) {sorted(unknown)}; known: {sorted(known)}")
        for key, sub in nested.items():
            value = node.get(key)
            if value is None:
                node.pop(key, None)
                continue
            sub_known = {f.name for f in dataclasses.fields(sub)}
            bad = set(value) - sub_known
            if bad:
                raise ValueError(
                    f"diagnosis.{key}: unknown setting(s) {sorted(bad)}; known: {sorted(sub_known)}"
                )
            node[key] = sub(**dict(value))
        if node.get("effects") is not None:
            node["effects"] = list(node["effects"])
        return cls(**node)
