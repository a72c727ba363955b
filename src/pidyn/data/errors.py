"""The error every data reader raises for input it cannot use."""

from __future__ import annotations


class DataError(ValueError):
    """Raised for unusable measurement files; the message names the file and the problem."""
