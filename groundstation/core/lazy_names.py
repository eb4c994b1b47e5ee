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


def lazy_dir(where: dict[str, str], namespace: dict[str, Any]) -> Callable[[], list[str]]:
    """The `__dir__` for the same package: its lazy names listed before their first use."""

    def __dir__() -> list[str]:
        return sorted(set(namespace) | set(where))

    return __dir__


__all__ = ["lazy_dir", "lazy_getattr"]
