"""Lightning callbacks of the subperiod schedule."""

from pidyn.callbacks.clamp import ParameterClamp
from pidyn.callbacks.early_stopping import ParameterEarlyStopping
from pidyn.callbacks.progress import LineProgress

__all__ = ["LineProgress", "ParameterClamp", "ParameterEarlyStopping"]
