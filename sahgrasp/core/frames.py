"""Rigid placements as 4x4 homogeneous matrices (metres), and the few operations on them we need.

A placement ``T_a_b`` maps coordinates in frame ``b`` to frame ``a``: ``p_a = R p_b + t``. Anything
with a ``homogeneous`` attribute (a ``pinocchio.SE3``) is accepted wherever a placement is.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FloatArray", "as_placement", "placement", "rotation_about", "transform_points"]

FloatArray = NDArray[np.float64]
"""A float64 numpy array."""


def as_placement(value: Any) -> FloatArray:
    """Return ``value`` (a 4x4 array-like or a ``pinocchio.SE3``) as a read-only rigid 4x4 matrix.

    The tests are those of ``numpy.allclose(R @ R.T, I, atol=1e-9)``, ``numpy.isclose(det R, 1,
    atol=1e-9)`` and ``numpy.allclose(last row, [0, 0, 0, 1])`` (relative tolerance 1e-5),
    written out on the 16 floats: every clearance query of a grasp optimization validates the
    object's placement, and numpy's ``allclose`` costs tens of microseconds on a 3x3 block.

    Raises:
        ValueError: The matrix is not 4x4, not finite, or its rotation part is not a rotation.
    """
    matrix = np.array(getattr(value, "homogeneous", value), dtype=np.float64)
    rows = matrix.tolist()
    if matrix.shape != (4, 4) or not all(math.isfinite(x) for row in rows for x in row):
        raise ValueError(f"a placement must be a finite 4x4 matrix, got shape {matrix.shape}")
    if not _is_rigid(rows):
        raise ValueError("a placement's upper-left 3x3 block must be a rotation, last row 0 0 0 1")
    matrix.setflags(write=False)
    return matrix


def _is_rigid(m: list[list[float]]) -> bool:
    """Whether the 4x4 rows ``m`` hold a rotation and the last row 0 0 0 1 (see as_placement)."""
    (a, b, c, _), (d, e, f, _), (g, h, k, _), last = m
    diagonal = _ATOL_RAD + _RTOL
    if not (
        abs(a * a + b * b + c * c - 1.0) <= diagonal
        and abs(d * d + e * e + f * f - 1.0) <= diagonal
        and abs(g * g + h * h + k * k - 1.0) <= diagonal
        and abs(a * d + b * e + c * f) <= _ATOL_RAD
        and abs(a * g + b * h + c * k) <= _ATOL_RAD
        and abs(d * g + e * h + f * k) <= _ATOL_RAD
    ):
        return False
    det = a * (e * k - f * h) - b * (d * k - f * g) + c * (d * h - e * g)
    return (
        abs(det - 1.0) <= diagonal
        and abs(last[0]) <= 1e-8
        and abs(last[1]) <= 1e-8
        and abs(last[2]) <= 1e-8
        and abs(last[3] - 1.0) <= 1e-8 + _RTOL
    )


_ATOL_RAD = 1e-9
"""Absolute tolerance of a placement's rotation block (R R^T = I, det R = 1)."""
_RTOL = 1e-5
"""Relative tolerance, numpy's default for ``allclose``/``isclose``."""


def placement(
    rotation: ArrayLike | None = None, translation_m: ArrayLike = (0, 0, 0)
) -> FloatArray:
    """Return the placement with the given rotation (default identity) and translation [m]."""
    matrix = np.eye(4)
    if rotation is not None:
        matrix[:3, :3] = rotation
    matrix[:3, 3] = translation_m
    return as_placement(matrix)


def rotation_about(axis: ArrayLike, angle_rad: float) -> FloatArray:
    """Return the rotation matrix of ``angle_rad`` about ``axis`` (normalised here)."""
    k = np.asarray(axis, dtype=np.float64)
    k = k / np.linalg.norm(k)
    skew = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle_rad) * skew + (1.0 - np.cos(angle_rad)) * (skew @ skew)


def transform_points(T: FloatArray, points: ArrayLike) -> FloatArray:
    """Apply placement ``T`` to points of shape (..., 3)."""
    return np.asarray(points, dtype=np.float64) @ T[:3, :3].T + T[:3, 3]
