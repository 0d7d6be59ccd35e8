"""Names a package exports but imports only on first use (PEP 562).

``crowdnav.agents`` and ``crowdnav.evaluation`` re-export names from their modules this way,
so that importing the package, or one of its light modules (``crowdnav.agents.training.seeding``,
``crowdnav.agents.runs.folder``, ``crowdnav.evaluation.protocol``), does not load torch, pandas
or matplotlib until one of those names is used.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_exports(package: str, exports: Mapping[str, str], namespace: dict[str, Any]) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package`` whose name ``n`` lives in module ``exports[n]``.

    ``namespace`` is the package's ``globals()``: a name is imported once, then cached there.
    """

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(exports))

    return __getattr__, __dir__
