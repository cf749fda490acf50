"""Local geometry of the manifold: Newton projection (Eq. (15)), tangent spaces, their signs."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgesdd as _dgesdd
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dgetrf as _dgetrf
from scipy.linalg.lapack import dorgqr as _dorgqr

from sahgrasp.atlas.model import FloatArray, Function

__all__ = ["Point", "crossing_sign", "min_cosine", "project", "regular_point"]

RANK_TOL = 1e-8  # relative size of the smallest R diagonal of qr(J^T) below which J drops rank


def project(
    F: Function,
    J: Function,
    x_tilde: FloatArray,
    phi: FloatArray,
    tol: float = 1e-10,
    max_iter: int = 20,
) -> FloatArray | None:
    """Orthogonal projection of ``x_tilde`` onto ``F = 0`` along the chart basis ``phi``.

    Solves ``F(x) = 0, phi^T (x - x_tilde) = 0`` (Eq. (15)) by Newton's method from ``x_tilde``.
    Every Newton step keeps ``phi^T (x - x_tilde) = 0`` exactly, so only ``F`` is monitored.

    Args:
        F: Residual, ``R^n -> R^(n-k)``.
        J: Jacobian of ``F``, ``R^n -> R^((n-k) x n)``.
        x_tilde: Point to project, shape (n,).
        phi: Orthonormal basis (n, k) of the chart's tangent space.
        tol: Convergence tolerance on ``|F(x)|``.
        max_iter: Largest number of Newton iterations.

    Returns:
        The projected point, or None when Newton's method did not converge.
    """
    n, k = phi.shape
    m = n - k
    A = np.empty((n, n))
    A[m:] = phi.T
    rhs = np.zeros(n)
    x = x_tilde
    tol2 = tol * tol
    for _ in range(max_iter):
        f = F(x)
        if f @ f <= tol2:
            return x
        A[:m] = J(x)
        rhs[:m] = -f
        dx, info = _dgesv(A, rhs)[2:]  # Eq. (15), linearised
        if info != 0:
            return None
        x = x + dx  # a NaN from F or J never meets the tolerance: the loop ends with None
    return None


def tangent(jac: FloatArray, k: int, scale: float = 0.0) -> tuple[FloatArray, float] | None:
    """Null-space basis ``phi`` (n x k) of ``jac`` and the sign of ``det([J; phi^T])``.

    From ``J^T = Q R`` (Householder): ``phi`` is the last k columns of Q, and
    ``det([J; phi^T]) = det(R_1) det(Q)`` with ``det(Q) = (-1)^(number of reflections)``.
    Returns None when ``J`` drops rank (a singular point): a diagonal entry of R below
    ``RANK_TOL`` times the largest one, or times ``scale`` (that of the start point), whichever is
    larger; the latter catches ``J -> 0`` when F has a single equation.
    """
    m, n = jac.shape
    qr, tau, _, _ = _dgeqrf(jac.T)
    diag = qr.diagonal().tolist()  # plain Python: m is small and numpy calls cost more
    size = [abs(d) for d in diag]
    if min(size) <= RANK_TOL * max(*size, scale):
        return None
    full = np.empty((n, n))
    full[:, :m] = qr
    q = _dorgqr(full, tau)[0]
    flips = sum(d < 0 for d in diag) + sum(t != 0 for t in tau.tolist())
    return q[:, m:], -1.0 if flips % 2 else 1.0


def crossing_sign(phi_i: FloatArray, phi_j: FloatArray, sign_j: float) -> float:
    """Sign of ``det([J(x_j); phi_i^T])`` from chart j's own sign.

    ``phi_i^T`` minus its component along the rows of ``J`` is ``(phi_i^T phi_j) phi_j^T``, so
    ``det([J; phi_i^T]) = det(phi_i^T phi_j) det([J; phi_j^T])``. A change of this sign between
    ``x_i`` and ``x_j`` means the path crossed a point where ``J`` or the chart degenerates.
    """
    lu, piv, _ = _dgetrf(phi_i.T @ phi_j)
    flips = sum(d < 0 for d in lu.diagonal().tolist())
    flips += sum(p != row for row, p in enumerate(piv.tolist()))
    return -sign_j if flips % 2 else sign_j


def min_cosine(phi_i: FloatArray, phi_j: FloatArray) -> float:
    """Smallest singular value of ``phi_i^T phi_j``: the norm of Eq. (18)."""
    return float(_dgesdd(phi_i.T @ phi_j, compute_uv=0)[1][-1])


class Point(NamedTuple):
    """A regular point of the manifold with its tangent basis and ``sign(det([J; phi^T]))``."""

    x: FloatArray
    phi: FloatArray
    sign: float


def regular_point(J: Function, x: FloatArray, k: int, scale: float = 0.0) -> Point | None:
    """``x`` with its tangent space, or None when ``J(x)`` drops rank (see :func:`tangent`)."""
    basis = tangent(J(x), k, scale)
    return None if basis is None else Point(x, *basis)
