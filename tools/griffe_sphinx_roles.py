"""Griffe extension for the API reference: Sphinx cross-reference roles become mkdocs links.

The docstrings are Google style and cross-reference with Sphinx roles (:class:`Hand`,
:func:`~sahgrasp.ik.solve_ik`, :meth:`Hand.integrate`), which Markdown would print verbatim. Each
role is resolved in the scope of the object whose docstring holds it (as Python would resolve the
name there) and rewritten as an autorefs link to the rendered object. A name that resolves outside
sahgrasp (numpy, Pinocchio, the standard library) or to a private object stays plain code; a name
that does not resolve at all is logged as a warning, so ``mkdocs build --strict`` fails on it.
Loaded by mkdocs.yml (``extensions:``).
"""

from __future__ import annotations

import importlib.util
import re
from typing import Any

import griffe

ROLE = re.compile(
    r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const):`(?P<body>[^`]+)`",
)
EXPLICIT = re.compile(r"(?P<title>.*?)\s*<(?P<target>[^>]+)>$")
PACKAGE = "sahgrasp"

_logger = griffe.get_logger("griffe_sphinx_roles")


def _resolve(obj: griffe.Object, name: str) -> str | None:
    """Absolute path of ``name`` in ``obj``'s scope, or None when Python could not find it."""
    head, _, rest = name.partition(".")
    if head == PACKAGE:
        return name
    try:
        base = obj.resolve(head)
    except griffe.NameResolutionError:
        # A dotted name of another installed package, e.g. concurrent.futures.Executor.
        return name if rest and importlib.util.find_spec(head) else None
    return f"{base}.{rest}" if rest else base


def _private(path: str) -> bool:
    """Whether the reference leaves out ``path`` (filters: ``!^_``), so a link would dangle."""
    return any(part.startswith("_") and not part.endswith("__") for part in path.split("."))


def _link(obj: griffe.Object, body: str) -> str:
    """Markdown for one role's body: ``name``, ``~a.b``, ``!name`` or ``title <target>``."""
    explicit = EXPLICIT.match(body)
    title, target = (explicit["title"], explicit["target"]) if explicit else (None, body)
    if target.startswith("!"):
        return f"`{title or target[1:]}`"
    short = target.startswith("~")
    target = target.lstrip("~")
    text = title or (target.rsplit(".", 1)[-1] if short else target)
    path = _resolve(obj, target)
    if path is None:
        location = f"{obj.filepath}:{obj.docstring.lineno if obj.docstring else obj.lineno}"
        _logger.warning("%s: cross-reference %r does not resolve in %s", location, target, obj.path)
        return f"`{text}`"
    if not path.startswith(f"{PACKAGE}.") or _private(path):
        return f"`{text}`"
    return f"[`{text}`][{path}]"


class SphinxRoles(griffe.Extension):
    """Rewrites the Sphinx roles of every docstring once the whole package is loaded."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        """Rewrite every docstring of ``pkg`` and of all its members."""
        self._rewrite(pkg)

    def _rewrite(self, obj: griffe.Object) -> None:
        if obj.docstring is not None:
            obj.docstring.value = ROLE.sub(lambda m: _link(obj, m["body"]), obj.docstring.value)
        for member in obj.members.values():
            if isinstance(member, griffe.Object):  # an alias is rewritten where it is defined
                self._rewrite(member)
