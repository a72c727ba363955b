"""The refinement's settings (``conf/model/refine/multiple_shooting.yaml`` overrides them): plain
types, so that Hydra takes them as the config's schema, checked by ``__post_init__``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

StateSource = Literal["networks", "measured", "simulated", "integrated"]
STATE_SOURCES = ("networks", "measured", "simulated", "integrated")
InitialState = Literal["auto", "free", "rest"]
INITIAL_STATES = ("auto", "free", "rest")


@dataclass
class RefineSettings:
    """How the shooting problem is set up and solved (the schema of ``model.refine``)."""

    segment_length: float = 1.0  # s; shorter segments give a smoother cost (Ribeiro et al. 2020)
    states: str = "networks"  # segment initial states: networks | measured | simulated | integrated
    substeps: int = 4  # RK4 steps per sample interval
    initial_state: str = "auto"  # rest | free | auto: at rest unless the data reject it
    rest_test_level: float = 0.01  # auto: false-rejection rate of the likelihood-ratio test of rest
    penalty_start: float = 100.0  # first continuity weight, relative to a segment's data term
    penalty_tol: float = 1e-6  # stage 1 ends when every continuity defect is below this (state scales)
    max_nfev: int = 100  # Levenberg-Marquardt evaluations per penalty round
    gn_steps: int = 40  # constrained Levenberg-Marquardt steps at most (stage 2; most runs need a few)
    reweight: bool = True  # weight each channel by its estimated noise and finish again
    period_scan: bool = True  # linear models: look for a lower basin of the period (``period_scan``)
    #: one linear mode: the period's profile-likelihood interval (``period_profile``)
    period_profile: bool = True
    #: several records: output-error evaluations from rest that finish the estimate (``polish``); 0: none
    polish_several: int = 20

    def __post_init__(self) -> None:
        if self.states not in STATE_SOURCES:
            raise ValueError(f"refine.states must be one of {', '.join(STATE_SOURCES)}; got '{self.states}'")
        if self.initial_state not in INITIAL_STATES:
            raise ValueError(
                f"refine.initial_state must be one of {', '.join(INITIAL_STATES)}; got '{self.initial_state}'"
            )
        if not 0 < self.rest_test_level < 1:
            raise ValueError(f"refine.rest_test_level must lie in (0, 1), got {self.rest_test_level}")
        if self.segment_length is not None and self.segment_length <= 0:
            raise ValueError(f"refine.segment_length must be > 0 s, got {self.segment_length}")
