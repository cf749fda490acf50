"""Optional dependencies, installed by the extras of pyproject.toml, and the one error when missing.

``pip install sahgrasp`` gives the IK, the planner, the scenes and every command; the extras add
what a few paths need: ``cluster`` (Dask, for a ``--scheduler`` or a ``dask.distributed.Client``),
``plot`` (matplotlib, for the figures written as images) and ``sim`` (MuJoCo, for the physics hold
test). A path that needs one calls :func:`require_extra` first, so that a missing package is one
line naming its extra (:class:`~sahgrasp.core.errors.MissingExtraError`), before any work.
"""

from __future__ import annotations

import importlib
from types import ModuleType

from sahgrasp.core.errors import MissingExtraError

__all__ = ["EXTRAS", "has_extra", "install_hint", "require_extra"]

EXTRAS: dict[str, tuple[str, str]] = {
    "cluster": ("dask.distributed", "Dask"),
    "plot": ("matplotlib", "matplotlib"),
    "sim": ("mujoco", "MuJoCo"),
}
"""Extra -> (the module it provides, the package's name as users know it)."""


def install_hint(extra: str) -> str:
    """The command that installs ``extra``: ``pip install "sahgrasp[EXTRA]"``."""
    return f'pip install "sahgrasp[{extra}]"'


def require_extra(extra: str, purpose: str) -> ModuleType:
    """Import the module of ``extra``, or raise naming the extra that installs it.

    Args:
        extra: A key of :data:`EXTRAS`.
        purpose: What needs it, the start of the message (``"--scheduler"``).

    Returns:
        The imported module.

    Raises:
        MissingExtraError: The module cannot be imported.
        KeyError: ``extra`` is not a key of :data:`EXTRAS` (a programming error).
    """
    module, package = EXTRAS[extra]
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingExtraError(
            extra, f"{purpose} needs {package}: {install_hint(extra)}"
        ) from None


def has_extra(extra: str) -> bool:
    """True when the module of ``extra`` (a key of :data:`EXTRAS`) imports."""
    try:
        require_extra(extra, extra)
    except MissingExtraError:
        return False
    return True
