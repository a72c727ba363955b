"""Lightning callbacks of the subperiod schedule."""

from pidyn.callbacks.clamp import ParameterClamp
from pidyn.callbacks.early_stopping import ParameterEarlyStopping

__all__ = ["ParameterClamp", "ParameterEarlyStopping"]
