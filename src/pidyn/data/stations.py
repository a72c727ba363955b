"""The stations pidyn knows (``pidyn/data/measured/stations.yaml``): each direction's channel sets
and, for a bridge, where its channels stand along the deck."""

from __future__ import annotations

import re
from collections.abc import Mapping
from importlib import resources
from typing import Any

import yaml

from pidyn.data.errors import DataError

STATIONS_FILE = "stations.yaml"


def stations() -> dict:
    """Every known station's entry, by its id (``CE89324``)."""
    ref = resources.files("pidyn.data.measured").joinpath(STATIONS_FILE)
    with ref.open("r", encoding="utf-8") as fh:
        return dict(yaml.safe_load(fh) or {})


def station_number(name: Any) -> str:
    """``CE89324``, ``89324`` and ``ce89324`` name one station."""
    m = re.search(r"(\d+)", str(name))
    return str(int(m.group(1))) if m else str(name).strip().upper()


def station_entry(station: str | None) -> dict:
    """The station's entry in ``stations.yaml`` (empty when it has none)."""
    if station is None:
        return {}
    return next((v for k, v in stations().items() if station_number(k) == station_number(station)), {})


def station_layout(station: str | None, layout: Mapping[str, Any] | None = None) -> dict:
    """``{"length": L, "positions": {channel: m}}`` of ``station`` (or ``layout`` as given)."""
    if layout is None:
        if station is None:
            raise DataError(
                "system=rigid_deck needs the station's layout: set data.station=<id> (stations.yaml) or "
                "system.layout={length: L, positions: {channel: m, ...}}"
            )
        layout = station_entry(station).get("layout")
        if layout is None:
            raise DataError(
                f"station {station}: {STATIONS_FILE} gives no positions of its channels along the deck; "
                "give system.layout={length: L, positions: {channel: m, ...}}"
            )
    length = float(layout.get("length", 0.0))
    positions = {int(c): float(s) for c, s in dict(layout.get("positions") or {}).items()}
    if not length > 0 or not positions:
        raise DataError(f"station {station}: a layout needs a positive length and channel positions")
    return {"length": length, "positions": positions}
