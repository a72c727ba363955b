"""The diagnosis's verdicts, one closed set: an enum whose values are the strings that
``diagnosis.json`` holds (``Verdict.NONE == "none"``), so files and comparisons stay as they were."""

from __future__ import annotations

from enum import Enum


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
    import yaml

    yaml.SafeDumper.add_representer(Verdict, lambda dumper, v: dumper.represent_str(v.value))


_register_yaml()
