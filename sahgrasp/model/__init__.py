"""The hand and the grasp targets.

:mod:`~sahgrasp.model.hand` holds hand descriptions and the Pinocchio model,
:mod:`~sahgrasp.model.hand_checks` validates descriptions, :mod:`~sahgrasp.model.contacts` the
contact targets and their JSON.
"""

from __future__ import annotations

__all__: list[str] = []
