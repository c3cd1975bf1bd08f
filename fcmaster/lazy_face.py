"""Package faces that import a name's module the first time the name is used (PEP 562).

A face such as :mod:`fcmaster.bus` lists its public names in ``__all__``, but importing one
module below it (``fcmaster.bus.plan``, which the config needs) must not load everything
the face offers (the master, structlog, pyserial). So the face's ``__getattr__`` imports a
name's module on first use and keeps the value in the package, where the next use finds it
as a plain attribute; ``dir()`` lists every public name, loaded or not. Type checkers see
the same names through the face's ``if TYPE_CHECKING:`` imports.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping

__all__ = ["lazy_face"]


def lazy_face(
    package: str, public: Iterable[str], modules: Mapping[str, Iterable[str]]
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """``__getattr__`` and ``__dir__`` for ``package``, whose ``public`` names live below it.

    ``modules`` maps each module to the public names it defines; together they must be
    exactly ``public`` (the face's ``__all__``), else the face raises as it is imported.
    """
    where = {name: module for module, names in modules.items() for name in names}
    missing, unknown = set(public) - set(where), set(where) - set(public)
    if missing or unknown:
        raise ImportError(
            f"{package}: no module given for {sorted(missing)}; not in __all__: {sorted(unknown)}"
        )
    namespace = sys.modules[package].__dict__

    def __getattr__(name: str) -> object:
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def __dir__() -> list[str]:
        return sorted({*namespace, *where})

    return __getattr__, __dir__
