"""pidyn: physics-informed structural system identification (PIDynNet) with baselines and diagnosis.

The public surface, for notebooks and scripts (the command line is ``pidyn-train``,
``pidyn-diagnose``, ``pidyn-generalize``, ``pidyn-predict``):

- ``Record``: a measured record; ``Record.from_csv``, ``Record.from_at2``, ``Record.simulate``.
- ``identify(record, system, **options) -> Result``: PIDynNet and the refinement stage (``record``
  may be a list: several earthquakes of one structure); a
  ``Result`` carries the parameters with their 95 % intervals, the identified equation, the
  estimate's history, ``.to_frame()``, ``.plot()``, ``.save(dir)`` and ``Result.load(run_dir)``.
- ``predict(result, record) -> RecordPrediction``: a measured record the model never saw,
  simulated from rest and scored channel by channel; ``predict(result, "kobe")`` ->
  ``ResponsePrediction``: the paper's physics-only network prediction of an unseen ground motion.
- ``diagnose(record, nominal) -> Diagnosis``: what the nominal model misses, and the gain.
- ``make_system(name, **values)``, ``system_names()``: the structural systems of the configs.

Names load on first use, so ``import pidyn`` stays light for the command line.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

__version__ = "0.1.0"

_PUBLIC = {
    "Record": "pidyn.api",  # through the API, which resolves system names through the configs
    "identify": "pidyn.api",
    "predict": "pidyn.api",
    "diagnose": "pidyn.api",
    "Result": "pidyn.api",
    "ResponsePrediction": "pidyn.api",
    "RecordPrediction": "pidyn.api",
    "Diagnosis": "pidyn.api",
    "system_names": "pidyn.api",
    "make_system": "pidyn.config",
}
__all__ = sorted(_PUBLIC) + ["__version__"]


def __getattr__(name: str) -> Any:
    if name in _PUBLIC:
        return getattr(import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'pidyn' has no attribute '{name}'")


def __dir__() -> list[str]:
    return __all__
