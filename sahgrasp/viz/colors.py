"""Colours of the scenes: meshcat's integer RGB, finger marker colours, quality colour maps."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib import colormaps
from numpy.typing import ArrayLike, NDArray

from sahgrasp.model.hands import hand_entry

__all__ = [
    "FINGER_COLORS",
    "MARKER_COLOR",
    "QUALITY_COLORMAP",
    "finger_colors",
    "hex_color",
    "quality_colors",
]

FINGER_COLORS = {
    "thumb": (0.85, 0.15, 0.15, 1.0),
    "index": (0.1, 0.65, 0.2, 1.0),
    "middle": (0.95, 0.6, 0.05, 1.0),
    "ring": (0.6, 0.2, 0.75, 1.0),
}
"""Contact-marker colour of each finger by name (RGBA in [0, 1]), unless its hand gives its own."""

MARKER_COLOR = (0.9, 0.1, 0.6, 1.0)
"""Contact-marker colour of a finger without its own colour."""

QUALITY_COLORMAP = "RdYlGn"
"""Matplotlib colour map of quality values: red (low) to green (high), as in the atlas paper."""


def finger_colors(hand_name: str) -> dict[str, tuple[float, float, float, float]]:
    """Contact-marker colours of the fingers of hand ``hand_name``.

    :data:`FINGER_COLORS`, overridden by the colours the hand's registry entry gives
    (:attr:`sahgrasp.model.hands.HandEntry.finger_colors`).
    """
    entry = hand_entry(hand_name)
    return {**FINGER_COLORS, **(entry.finger_colors if entry is not None else {})}


def hex_color(rgba: Sequence[float]) -> int:
    """Return meshcat's ``0xRRGGBB`` of an RGB(A) colour with components in [0, 1]."""
    r, g, b = (round(255 * min(max(float(c), 0.0), 1.0)) for c in rgba[:3])
    return (r << 16) | (g << 8) | b


def quality_colors(values: ArrayLike, singular_below: float) -> NDArray[np.float64]:
    """RGB colours (N, 3) of quality values: red to green over their range, black if singular.

    Args:
        values: Quality index per point, shape (N,), finite.
        singular_below: Values below this are singular grasps, drawn black (atlas paper Fig. 9).

    Raises:
        ValueError: ``values`` is not a finite 1-D array.
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 1 or not np.all(np.isfinite(v)):
        raise ValueError(f"quality values must be a finite 1-D array, got shape {v.shape}")
    regular = v >= singular_below
    colors = np.zeros((v.size, 3))
    if regular.any():
        lo, hi = v[regular].min(), v[regular].max()
        scaled = (v[regular] - lo) / (hi - lo) if hi > lo else np.ones(int(regular.sum()))
        colors[regular] = colormaps[QUALITY_COLORMAP](scaled)[:, :3]
    return colors
