"""How an unseen response is solved: the settings of the physics-only prediction (Eq. 14), kept
apart from the solver so the config layer reads them without loading torch."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass
class PredictSettings:
    """How an unseen response is solved; the schema of ``generalize.yaml``'s ``generalization``
    node (``pidyn.schemas.GeneralizationNode`` adds which responses are predicted).

    ``start_from="identified"`` fine-tunes the identification networks literally; "fresh"
    (default) re-initialises them (seeded) once per excitation. Measured: a network carried
    from a strongly excited identification window can settle on a spurious free vibration
    in the quiet first window of a new record (Kobe x0.5, stretched 0.8: gamma 0.19 against
    0.98 from a fresh start).

    ``lbfgs_steps``: L-BFGS steps on the whole collocation pool after Adam in each window
    (0 = Adam only). Measured on Kobe x1.5, window 9-12 s from the true state: Adam's
    1500 iterations left the physics loss at 16 and x 170 % wrong; six L-BFGS steps reached
    0.006 and 4 %. A window whose Adam fit fails hands a wrong state to all later ones.

    ``split_tol``: a window whose final physics loss stays above it is solved again as two
    halves from the same start state and networks, down to ``min_window`` seconds (a loss
    that low is ~1e-5 on a solved window). Measured on Kobe x1.5 stretched 1.25 (k3 x^2 / k1
    up to 5): 3 s windows left one window at 0.05 and gave gamma 0.26; with splitting, 1.00.
    """

    iterations: int = 500  # physics-only Adam iterations per window
    lbfgs_steps: int = 30
    split_tol: float = 1e-3
    min_window: float = 0.75
    start_from: str = "fresh"  # fresh | identified

    def __post_init__(self) -> None:
        if self.start_from not in ("fresh", "identified"):
            raise ValueError(
                f"generalization.start_from: '{self.start_from}' is not one of fresh, identified"
            )
        if int(self.iterations) < 0 or int(self.lbfgs_steps) < 0:
            raise ValueError("generalization.iterations and lbfgs_steps must be >= 0")
        if not self.min_window > 0:
            raise ValueError(f"generalization.min_window must be > 0, got {self.min_window}")
