"""Small pieces shared by the subcommands."""

from __future__ import annotations

import json
from typing import Any

from sahgrasp.fileio import write_json_atomic

__all__ = ["emit_json"]


def emit_json(data: Any, out: str | None) -> None:
    """Write ``data`` to ``out`` atomically, or print it when ``out`` is ``-`` or None."""
    if out is None or out == "-":
        print(json.dumps(data, indent=2))
    else:
        write_json_atomic(out, data)
        print(f"wrote {out}")
