"""Optional dependencies, installed by the extras of pyproject.toml, and the one error when missing.

``pip install sahgrasp`` gives the IK, the planner, the scenes and every command; the extras add
what a few paths need: ``cluster`` (Dask, for a ``--scheduler`` or a ``dask.distributed.Client``),
``plot`` (matplotlib, for the figures written as images) and ``sim`` (MuJoCo, for the physics hold
test). A path that needs one calls :func:`require_extra` first, so that a missing package is one
line naming its extra (:class:`~sahgrasp.core.errors.MissingExtraError`), before any work.
"""

from __future__ import annotations

import importlib
import json
from types import ModuleType

from sahgrasp.core.errors import MissingExtraError

__all__ = [
    "EXTRAS",
    "has_extra",
    "install_command",
    "install_hint",
    "is_editable_install",
    "require_extra",
]

EXTRAS: dict[str, tuple[str, str]] = {
    "cluster": ("dask.distributed", "Dask"),
    "plot": ("matplotlib", "matplotlib"),
    "sim": ("mujoco", "MuJoCo"),
}
"""Extra -> (the module it provides, the package's name as users know it)."""


def install_hint(extra: str) -> str:
    """The command that installs ``extra``: ``pip install "sahgrasp[EXTRA]"``."""
    return install_command(extra, editable=False)


def install_command(extra: str, editable: bool | None = None) -> str:
    """The pip command that installs ``extra`` for this copy of sahgrasp.

    An editable install (``pip install -e .`` in a checkout) and a copy run from its source
    folder install an extra from that checkout, ``pip install -e ".[EXTRA]"``; any other
    install from the package's name, ``pip install "sahgrasp[EXTRA]"``.

    Args:
        extra: The extra's name in pyproject.toml (``bench``, ``sim``...).
        editable: Whether this copy is an editable install (default:
            :func:`is_editable_install`).
    """
    if editable is None:
        editable = is_editable_install()
    return f'pip install -e ".[{extra}]"' if editable else f'pip install "sahgrasp[{extra}]"'


def is_editable_install(distribution: str = "sahgrasp") -> bool:
    """True when ``distribution`` is installed in editable mode or not installed at all.

    The install kind comes from the ``direct_url.json`` that pip records (PEP 610). Not
    installed means run from a source folder (``PYTHONPATH``): a checkout, like an editable
    install.
    """
    from importlib import metadata  # here: most commands never ask, and it takes 10 ms to import

    try:
        dist = metadata.distribution(distribution)
    except metadata.PackageNotFoundError:
        return True
    if str(getattr(dist, "_path", "")).endswith(".egg-info"):
        return True  # setuptools' metadata in a source checkout, found first from inside it
    try:
        direct = json.loads(dist.read_text("direct_url.json") or "{}")
    except ValueError:
        return False
    return bool(isinstance(direct, dict) and direct.get("dir_info", {}).get("editable"))


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
