"""Names a package imports on first use (PEP 562), so that importing the package stays light
(``import hybridneus`` needs no torch; a fit that reads a scene frame needs no readers)."""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any


def lazy_getattr(package: str, modules: dict[str, str],
                 namespace: dict[str, Any]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package``: a name of ``modules`` (name -> the module
    that defines it, a full dotted path) is imported on first use and kept in ``namespace``
    (the package's ``globals()``); any other name is an ``AttributeError``."""

    def __getattr__(name: str) -> Any:
        module = modules.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    return __getattr__
