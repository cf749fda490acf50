"""Checks of the user's problem and the start point, with messages saying what is valid."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from sahgrasp.atlas.model import AtlasSettings, FloatArray, Function
from sahgrasp.atlas.projection import Point, project, regular_point
from sahgrasp.core.errors import AtlasError

__all__ = ["check_bounds", "start_point"]


def check_bounds(value: ArrayLike | None, n: int, fill: float, what: str) -> FloatArray:
    """``value`` as ``n`` box bounds (``fill`` everywhere when None).

    Raises:
        AtlasError: ``value`` is not ``n`` numbers or holds NaN.
    """
    if value is None:
        return np.full(n, fill)
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,) or np.isnan(arr).any():
        raise AtlasError(f"{what} must be {n} numbers (use +-inf for no bound), got {arr!r}")
    return arr


def start_point(F: Function, J: Function, x0: ArrayLike, k: int, settings: AtlasSettings) -> Point:
    """Check the problem at ``x0`` and project ``x0`` onto the manifold."""
    x = np.asarray(x0, dtype=np.float64)
    if x.ndim != 1 or not np.isfinite(x).all():
        raise AtlasError(f"x0 must be a finite 1-D vector, got shape {x.shape}")
    n = x.size
    if not 1 <= k < n:
        raise AtlasError(f"k must satisfy 1 <= k < n = {n}, got k = {k}")
    f, jac = F(x), J(x)
    if not (isinstance(f, np.ndarray) and isinstance(jac, np.ndarray)):
        raise AtlasError(f"F and J must return numpy arrays, got {type(f)} and {type(jac)}")
    if f.shape != (n - k,) or jac.shape != (n - k, n):
        raise AtlasError(
            f"F(x) must have shape ({n - k},) and J(x) shape ({n - k}, {n}) for a {k}-manifold "
            f"in R^{n}; got {f.shape} and {jac.shape}"
        )
    if not (np.isfinite(f).all() and np.isfinite(jac).all()):
        raise AtlasError("F(x0) or J(x0) holds NaN or inf")
    if np.linalg.norm(f) > settings.start_tol:
        raise AtlasError(
            f"x0 is off the manifold: |F(x0)| = {np.linalg.norm(f):.3g} > start_tol = "
            f"{settings.start_tol:.3g}; pass a point with |F(x0)| <= start_tol"
        )
    point = regular_point(J, x, k)
    if point is None:
        raise AtlasError(
            f"J(x0) has rank {np.linalg.matrix_rank(jac)} < n - k = {n - k}: x0 is a singular "
            f"point, or the solution set has a dimension larger than k = {k}; pass a regular start "
            "point and k = n - rank(J)"
        )
    projected = project(F, J, x, point.phi, settings.newton_tol, settings.newton_max_iter)
    point = None if projected is None else regular_point(J, projected, k)
    if point is None:
        raise AtlasError("the Newton projection of x0 onto F = 0 failed or met a singular point")
    return point
