"""Classical identification on the same data as PIDynNet, and the Cramer-Rao bound."""

from pidyn.baselines.common import BaselineResult
from pidyn.baselines.cramer_rao import cramer_rao
from pidyn.baselines.least_squares import equation_error, output_error
from pidyn.baselines.sindy import weak_sindy
from pidyn.baselines.ukf import unscented_kalman_filter
from pidyn.simulate import simulate_batch

__all__ = [
    "BaselineResult",
    "cramer_rao",
    "simulate_batch",
    "equation_error",
    "output_error",
    "unscented_kalman_filter",
    "weak_sindy",
]
