"""How to install an optional extra of sahgrasp, said the way this copy was installed.

An editable install (``pip install -e .`` in a checkout) and a copy run from its source folder
install an extra from that checkout, ``pip install -e ".[bench]"``; any other install (``pip install
sahgrasp`` or ``pip install .``) from the package's name, ``pip install "sahgrasp[bench]"``. The
install kind comes from the ``direct_url.json`` that pip records (PEP 610).
"""

from __future__ import annotations

import json
from importlib import metadata

__all__ = ["install_command", "is_editable_install"]


def is_editable_install(distribution: str = "sahgrasp") -> bool:
    """True when ``distribution`` is installed in editable mode or not installed at all.

    Not installed means run from a source folder (``PYTHONPATH``): a checkout, like an editable
    install.
    """
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


def install_command(extra: str, editable: bool | None = None) -> str:
    """The pip command that installs ``extra`` for this copy of sahgrasp.

    Args:
        extra: The extra's name in pyproject.toml (``bench``, ``sim``...).
        editable: Whether this copy is an editable install (default: looked up).
    """
    if editable is None:
        editable = is_editable_install()
    return f'pip install -e ".[{extra}]"' if editable else f'pip install "sahgrasp[{extra}]"'
