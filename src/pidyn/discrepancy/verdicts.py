"""The diagnosis's verdicts, one closed set: an enum whose values are the strings that
``diagnosis.json`` holds (``Verdict.NONE == "none"``), so files and comparisons stay as they were."""

from __future__ import annotations

from enum import Enum
from typing import Any

import numpy as np
import yaml

from pidyn.notes import note


class Verdict(str, Enum):
    #: the nominal model explains the data (within the noise, on the held-out part too)
    NONE = "none"
    #: a named effect (or several) explains what the nominal model misses, with a held-out gain
    DISCREPANCY = "discrepancy"
    #: the nominal model misses something no library effect explains
    UNEXPLAINED = "unexplained"

    def __str__(self) -> str:
        return self.value


def _register_yaml() -> None:
    """A verdict in a YAML file is its plain string."""
    yaml.SafeDumper.add_representer(Verdict, lambda dumper, v: dumper.represent_str(v.value))


_register_yaml()


def unearned_names(causes: list[str], gain: dict[str, Any], th) -> dict[str, Any] | None:
    """Library names that do not earn their place: the extended model predicts the held-out part
    no better than ``min_name_gain`` of the nominal model's error (an effect outside the library,
    a stiffness that drops only inside a band of displacement, came out as ``stiffness_loss`` with
    the held-out NRMSE 1.061 -> 1.033). The names, the two errors and a coded note; None when the
    names earn their place (or nothing is named)."""
    nominal, extended = gain.get("nominal"), gain.get("extended")
    if not causes or nominal is None or extended is None:
        return None
    if np.isfinite(extended) and extended <= (1.0 - float(th.min_name_gain)) * nominal:
        return None
    return {
        "causes": list(causes),
        "heldout_nominal": nominal,
        "heldout_extended": extended,
        "note": note(
            "name_unearned",
            f"{' + '.join(causes)} extended the model, but the extended model predicts the held-out part "
            f"no better (NRMSE {nominal:.4g} -> {extended:.4g}, at least {100 * th.min_name_gain:g} % less "
            "required): no library name is kept, the model misses something the library does not hold",
        ),
    }
