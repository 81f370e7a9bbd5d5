"""Package faces that import on first use (PEP 562), shared by the project's three packages.

A package's ``__init__`` names its public API with `lazy_exports`; ``import formation_sim`` then
costs nothing, and ``formation_sim.simulate`` imports `formation_sim.sim.engine` when first used.
This keeps node processes and the ``formation`` command quick to start: the model's scipy, the
figures' matplotlib and the runtime's rclpy load only where they are needed.
"""

from __future__ import annotations

import importlib
from collections.abc import Mapping, Sequence
from typing import Any


def lazy_exports(namespace: dict[str, Any], exports: Mapping[str, Sequence[str]]) -> list[str]:
    """Install ``__getattr__`` and ``__dir__`` into a package's `namespace`; return its ``__all__``.

    `exports` maps a submodule (relative to the package) to the public names it defines.
    """
    package = namespace['__name__']
    where = {name: module for module, names in exports.items() for name in names}

    def __getattr__(name: str) -> Any:
        module = where.get(name)
        if module is None:
            raise AttributeError(f'module {package!r} has no attribute {name!r}')
        value = getattr(importlib.import_module(f'{package}.{module}'), name)
        namespace[name] = value  # later lookups skip __getattr__
        return value

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    namespace['__getattr__'] = __getattr__
    namespace['__dir__'] = __dir__
    return sorted(where)
