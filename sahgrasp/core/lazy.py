"""Names of a package loaded on first use (PEP 562).

A package's ``__init__`` lists which submodule defines each public name; a name is imported the
first time it is read, so that importing the package, or one of its submodules, does not load
every sibling's dependencies (``import sahgrasp`` and ``sahgrasp --help`` stay fast).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterable, Mapping, MutableMapping
from typing import Any

__all__ = ["lazy_exports"]


def lazy_exports(
    package: str, namespace: MutableMapping[str, Any], exports: Mapping[str, Iterable[str]]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` of a package with lazily loaded names.

    Args:
        package: The package's ``__name__``.
        namespace: The package's ``globals()``: a name read once is kept there.
        exports: Per submodule (dotted name), the names it defines that the package exports.

    Returns:
        ``(__getattr__, __dir__)``, to assign at the package's module level.
    """
    module_of = {name: module for module, names in exports.items() for name in names}

    def getattr_(name: str) -> Any:
        module = module_of.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    def dir_() -> list[str]:
        return sorted(set(namespace) | set(module_of))

    return getattr_, dir_
