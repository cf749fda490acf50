"""Rigid placements as 4x4 homogeneous matrices (metres), and the few operations on them we need.

A placement ``T_a_b`` maps coordinates in frame ``b`` to frame ``a``: ``p_a = R p_b + t``. Anything
with a ``homogeneous`` attribute (a ``pinocchio.SE3``) is accepted wherever a placement is.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = ["FloatArray", "as_placement", "placement", "rotation_about", "transform_points"]

FloatArray = NDArray[np.float64]
"""A float64 numpy array."""


def as_placement(value: Any) -> FloatArray:
    """Return ``value`` (a 4x4 array-like or a ``pinocchio.SE3``) as a read-only rigid 4x4 matrix.

    Raises:
        ValueError: The matrix is not 4x4, not finite, or its rotation part is not a rotation.
    """
    matrix = np.array(getattr(value, "homogeneous", value), dtype=np.float64)
    if matrix.shape != (4, 4) or not np.all(np.isfinite(matrix)):
        raise ValueError(f"a placement must be a finite 4x4 matrix, got shape {matrix.shape}")
    rotation = matrix[:3, :3]
    if not (
        np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-9)
        and np.isclose(np.linalg.det(rotation), 1.0, atol=1e-9)
        and np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0])
    ):
        raise ValueError("a placement's upper-left 3x3 block must be a rotation, last row 0 0 0 1")
    matrix.setflags(write=False)
    return matrix


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
