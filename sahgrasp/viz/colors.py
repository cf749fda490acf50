"""Colours of the scenes: meshcat's integer RGB, finger marker colours, quality colour maps."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.model.hands import hand_entry

__all__ = [
    "FINGER_COLORS",
    "MARKER_COLOR",
    "QUALITY_COLORMAP",
    "RDYLGN_RGB",
    "finger_colors",
    "hex_color",
    "quality_colormap",
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
"""Name of the colour map of quality values: red (low) to green (high), as in the atlas paper."""

RDYLGN_RGB = (
    (165, 0, 38),
    (215, 48, 39),
    (244, 109, 67),
    (253, 174, 97),
    (254, 224, 139),
    (255, 255, 191),
    (217, 239, 139),
    (166, 217, 106),
    (102, 189, 99),
    (26, 152, 80),
    (0, 104, 55),
)
"""The eleven colours (8-bit RGB) of the diverging scheme RdYlGn of ColorBrewer (Cynthia A.
Brewer, colorbrewer2.org, Apache-2.0), evenly spaced from 0 to 1: the anchors of matplotlib's
``RdYlGn`` colour map, stored here so that the scenes need no matplotlib."""

_LUT_SIZE = 256
"""Entries of the colour table, as matplotlib's colour maps have."""

_RDYLGN_LUT = np.stack(
    [
        np.interp(
            np.linspace(0.0, 1.0, _LUT_SIZE),
            np.linspace(0.0, 1.0, len(RDYLGN_RGB)),
            np.array(RDYLGN_RGB, dtype=np.float64)[:, channel] / 255.0,
        )
        for channel in range(3)
    ],
    axis=1,
)
_RDYLGN_LUT.setflags(write=False)


def quality_colormap(scaled: ArrayLike) -> NDArray[np.float64]:
    """RGB colours (N, 3) of values in [0, 1] on the RdYlGn map (:data:`RDYLGN_RGB`).

    The anchors are interpolated linearly into a table of 256 colours, which a value indexes as
    a matplotlib colour map does (``floor(256 x)``, 1 in the last entry; outside [0, 1]
    clipped): the colours equal matplotlib's ``colormaps["RdYlGn"]`` to rounding.
    """
    x = np.asarray(scaled, dtype=np.float64).reshape(-1)
    index = np.clip((x * _LUT_SIZE).astype(np.int64), 0, _LUT_SIZE - 1)
    return _RDYLGN_LUT[index].copy()


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
        colors[regular] = quality_colormap(scaled)
    return colors
