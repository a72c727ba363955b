"""Objects by name, filled by the layer that knows the names: ``Record.simulate("duffing")`` in the
data layer takes a system by its name, and names resolve through the package's configs, which
only ``pidyn.config`` reads. It puts its resolver here; the data layer looks it up."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

#: "system": name, **values -> a structural system (``pidyn.config.make_system``)
RESOLVERS: dict[str, Callable[..., Any]] = {}
