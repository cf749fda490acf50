"""Old module paths of sahgrasp, still importable for one release with a DeprecationWarning.

The flat modules moved into packages (``sahgrasp.hand`` is ``sahgrasp.model.hand``). Rather than
one shim file per old path, :data:`MOVED` maps each old name to the new one and
:class:`MovedModuleFinder`, installed first in ``sys.meta_path`` by ``sahgrasp/__init__.py``,
answers an import of an old name with the new module itself (the same object, so that
``isinstance`` checks and module state agree) after warning. The finder sits first, so that no
other finder (an older copy of sahgrasp on the path, say) answers an old name; it answers nothing
but the old names. Old paths that are packages now
(``sahgrasp.collision``, ``sahgrasp.quality``, ``sahgrasp.optimization``) need no alias: their
``__init__`` re-exports the old module's public names. Names that left a module that stays
(``sahgrasp.model.contacts.load_targets`` is ``sahgrasp.objects.targets.load_targets``) are in
:data:`MOVED_NAMES`, answered by :func:`moved_attribute` from the old module's ``__getattr__``.
"""

from __future__ import annotations

import importlib
import sys
import warnings
from collections.abc import Sequence
from importlib.machinery import ModuleSpec
from types import ModuleType
from typing import Any

__all__ = [
    "BECAME_PACKAGES",
    "MOVED",
    "MOVED_NAMES",
    "MovedModuleFinder",
    "install",
    "moved_attribute",
]

#: Old dotted module name -> its new name.
MOVED: dict[str, str] = {
    "sahgrasp.bench.extras": "sahgrasp.core.extras",
    "sahgrasp.contacts": "sahgrasp.model.contacts",
    "sahgrasp.errors": "sahgrasp.core.errors",
    "sahgrasp.fileio": "sahgrasp.core.fileio",
    "sahgrasp.grasp": "sahgrasp.optimization.grasp",
    "sahgrasp.hand": "sahgrasp.model.hand",
    "sahgrasp.hand_checks": "sahgrasp.model.hand_checks",
    "sahgrasp.motions": "sahgrasp.optimization.motions",
    "sahgrasp.objects.clearance": "sahgrasp.collision.hand_object",
    "sahgrasp.objects.collision": "sahgrasp.collision.shapes",
    "sahgrasp.objects.frames": "sahgrasp.core.frames",
    "sahgrasp.parallel": "sahgrasp.core.parallel",
    "sahgrasp.planar": "sahgrasp.optimization.planar",
    "sahgrasp.progress": "sahgrasp.core.progress",
    "sahgrasp.quality_indices": "sahgrasp.quality.indices",
    "sahgrasp.registry": "sahgrasp.core.registry",
    "sahgrasp.sequence.executors": "sahgrasp.core.executors",
    "sahgrasp.stream": "sahgrasp.ik.stream",
    "sahgrasp.tables": "sahgrasp.core.tables",
    "sahgrasp.wrench": "sahgrasp.quality.wrench",
}

#: Names that left a module that stays: old module -> {old name: "new.module:new name"}. The old
#: module's ``__getattr__`` (or, for a method, the method itself) calls :func:`moved_attribute`.
MOVED_NAMES: dict[str, dict[str, str]] = {
    "sahgrasp.model.contacts": {
        name: f"sahgrasp.objects.targets:{name}"
        for name in (
            "InvalidProblem",
            "MAX_PATH_CHARS",
            "ObjectCache",
            "QUATERNION_TOLERANCE",
            "TargetsFile",
            "load_targets",
            "object_spec",
            "problem_from_json",
            "problem_from_line",
            "read_problems",
            "read_targets_document",
            "save_targets",
            "targets_hand",
        )
    }
    | {
        "GraspTarget.from_dict": "sahgrasp.objects.targets:problem_from_dict",
        "ObjectSpec.load": "sahgrasp.objects.targets:build_object",
    },
}

#: Old modules that are packages now: their old contents are these modules' public names.
BECAME_PACKAGES: dict[str, str] = {
    "sahgrasp.collision": "sahgrasp.collision.hand_self",
    "sahgrasp.optimization": "sahgrasp.optimization.optimizer",
    "sahgrasp.quality": "sahgrasp.quality.ellipsoids",
}


def moved_attribute(module: str, name: str) -> Any:
    """The name ``name`` of ``module`` from its new home (:data:`MOVED_NAMES`), after a warning.

    Raises:
        AttributeError: ``name`` is not a moved name of ``module`` (what ``getattr`` expects).
    """
    new = MOVED_NAMES.get(module, {}).get(name)
    if new is None:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new_module, new_name = new.split(":")
    warnings.warn(
        f"{module}.{name} moved to {new_module}.{new_name}; use {new_module}.{new_name} instead "
        "(the old name goes in the next release)",
        DeprecationWarning,
        stacklevel=3,
    )
    return getattr(importlib.import_module(new_module), new_name)


class _AliasLoader:
    """Loads an old name as the new module: the import system returns ``sys.modules[name]``."""

    def __init__(self, new: str) -> None:
        self.new = new

    def create_module(self, spec: ModuleSpec) -> None:
        return None  # a placeholder module, replaced in exec_module

    def exec_module(self, module: ModuleType) -> None:
        old = module.__name__
        warnings.warn(
            f"{old} moved to {self.new}; import {self.new} instead (the old name goes in the "
            "next release)",
            DeprecationWarning,
            stacklevel=2,
        )
        # After exec_module the import system returns whatever sys.modules holds under the old
        # name: the new module itself, not the placeholder.
        sys.modules[old] = importlib.import_module(self.new)


class MovedModuleFinder:
    """A ``sys.meta_path`` finder that resolves the old names of :data:`MOVED`."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None = None, target: ModuleType | None = None
    ) -> ModuleSpec | None:
        new = MOVED.get(fullname)
        if new is None:
            return None
        return ModuleSpec(fullname, _AliasLoader(new))  # type: ignore[arg-type]


def install() -> None:
    """Put the finder first in ``sys.meta_path``, once (importing sahgrasp twice adds nothing)."""
    if not any(isinstance(finder, MovedModuleFinder) for finder in sys.meta_path):
        sys.meta_path.insert(0, MovedModuleFinder())
