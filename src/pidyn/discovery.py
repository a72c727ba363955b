"""Finding a package's plug-ins by their files: every concrete subclass of a base class defined in
a module of the package, so that adding one is adding its file (the force terms, the effects)."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from collections.abc import Iterable


def defined_in(package: str, path: Iterable[str], base: type) -> list[type]:
    """The concrete subclasses of ``base`` that the modules of ``package`` (its ``__name__`` and
    ``__path__``) define themselves (not the ones they import), by module name, then source order."""
    found: list[type] = []
    for info in sorted(pkgutil.iter_modules(list(path)), key=lambda m: m.name):
        module = importlib.import_module(f"{package}.{info.name}")
        found += [
            obj
            for obj in vars(module).values()
            if inspect.isclass(obj)
            and issubclass(obj, base)
            and obj.__module__ == module.__name__
            and not inspect.isabstract(obj)
        ]
    return found
