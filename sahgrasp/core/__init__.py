"""Base utilities: errors, file writes, progress, tables, registries, rigid frames, process pools.

Nothing here knows a hand or an object; every other package may import these modules.
"""

from __future__ import annotations

__all__: list[str] = []
