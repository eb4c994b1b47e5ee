"""A package's public names imported on first use (PEP 562 module __getattr__), so that
importing one of its modules does not import all the others: a log writer process that
needs only the file layout, or a command that checks a name, starts without the rest."""

from __future__ import annotations

from importlib import import_module
from typing import Any, Callable


def lazy_getattr(package: str, where: dict[str, str],
                 namespace: dict[str, Any]) -> Callable[[str], Any]:
    """The `__getattr__` for `package`: a name of `where` (name -> module of the package)
    is imported from its module when first asked for, then kept in `namespace` (the
    package's globals) so later lookups do not come here."""

    def __getattr__(name: str) -> Any:
        if name in where:
            value = getattr(import_module(f".{where[name]}", package), name)
            namespace[name] = value
            return value
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    return __getattr__


__all__ = ["lazy_getattr"]
