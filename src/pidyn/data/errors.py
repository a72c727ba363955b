"""The error every data reader raises for input it cannot use."""

from __future__ import annotations


class DataError(ValueError):
    """Raised for unusable measurement files; the message names the file and the problem."""


def needed(value, message: str):
    """``value``, or a DataError saying ``message`` when it is None (a setting left unset)."""
    if value is None:
        raise DataError(message)
    return value
