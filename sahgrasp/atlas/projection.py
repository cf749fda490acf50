"""Local geometry of the manifold: Newton projection (Eq. (15)), tangent spaces, their signs."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgesdd as _dgesdd
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dgetrf as _dgetrf
from scipy.linalg.lapack import dorgqr as _dorgqr

from sahgrasp.atlas._polytope import det_signs, min_singular_values
from sahgrasp.atlas.model import FloatArray, Function

__all__ = [
    "Point",
    "crossing_sign",
    "crossing_signs",
    "min_cosine",
    "min_cosines",
    "project",
    "project_many",
    "regular_point",
    "tangent_many",
]

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


def _solve_stack(A: FloatArray, b: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
    """``A x = b`` for a stack (B, n, n); rows whose matrix is singular get ``ok = False``."""
    try:
        x = np.asarray(np.linalg.solve(A, b[..., None])[..., 0], dtype=np.float64)
        return x, np.ones(len(A), dtype=bool)
    except np.linalg.LinAlgError:  # one singular matrix fails the stack: solve row by row
        out, ok = np.zeros_like(b), np.ones(len(A), dtype=bool)
        for row, (a, rhs) in enumerate(zip(A, b, strict=True)):
            dx, info = _dgesv(a, rhs)[2:]
            out[row], ok[row] = dx, info == 0
        return out, ok


def project_many(
    F: Function,
    J: Function,
    x_tilde: FloatArray,
    phi: FloatArray,
    tol: float = 1e-10,
    max_iter: int = 20,
) -> tuple[FloatArray, NDArray[np.bool_]]:
    """:func:`project` for a stack of points, one stacked linear solve per Newton iteration.

    Args:
        F: Residual on a stack of points, ``(B, n) -> (B, n - k)``.
        J: Its Jacobian on a stack, ``(B, n) -> (B, n - k, n)``.
        x_tilde: Points to project, shape (B, n).
        phi: Orthonormal tangent bases of their charts, shape (B, n, k).
        tol: Convergence tolerance on ``|F(x)|``.
        max_iter: Largest number of Newton iterations per point.

    Returns:
        The projected points (B, n) and which of them converged (B,); each row takes exactly the
        iterations :func:`project` would.
    """
    B, n, k = phi.shape
    m = n - k
    x = x_tilde.copy()
    done = np.zeros(B, dtype=bool)
    # The points still moving, kept compact (their rows of x, of the Newton matrices [J; phi^T]
    # and their indices) and written back to x when they leave: fewer array calls per iteration.
    idx = np.flatnonzero(np.isfinite(x).all(axis=1))
    xa = x[idx]
    A = np.empty((idx.size, n, n))
    A[:, m:] = phi[idx].transpose(0, 2, 1)
    tol2 = tol * tol
    with np.errstate(over="ignore", invalid="ignore"):  # a diverging point is dropped below
        _iterate(F, J, x, done, idx, xa, A, m, n, tol2, max_iter)
    return x, done


def _iterate(
    F: Function, J: Function, x: FloatArray, done: NDArray[np.bool_], idx: NDArray[np.intp],
    xa: FloatArray, A: FloatArray, m: int, n: int, tol2: float, max_iter: int,
) -> None:  # fmt: skip
    """The Newton iterations of :func:`project_many`, writing into ``x`` and ``done``."""
    for _ in range(max_iter):
        if idx.size == 0:
            break
        f = F(xa)
        converged = (f * f).sum(axis=1) <= tol2
        if converged.any():
            done[idx[converged]] = True
            x[idx[converged]] = xa[converged]
            step = ~converged
            idx, xa, f, A = idx[step], xa[step], f[step], A[step]
            if idx.size == 0:
                break
        A[:, :m] = J(xa)
        rhs = np.zeros((idx.size, n))
        rhs[:, :m] = -f
        dx, solved = _solve_stack(A, rhs)  # Eq. (15), linearised
        xa = xa + dx
        moving = solved & np.isfinite(xa).all(axis=1)
        if not moving.all():
            x[idx[~moving]] = xa[~moving]
            idx, xa, A = idx[moving], xa[moving], A[moving]
    x[idx] = xa  # the last iterates of points that did not converge


def tangent_many(
    jac: FloatArray, k: int, scale: float = 0.0
) -> tuple[FloatArray, FloatArray, NDArray[np.bool_]]:
    """:func:`tangent` for a stack of Jacobians (B, n - k, n), by one stacked QR.

    Returns:
        Tangent bases (B, n, k), the signs of ``det([J; phi^T])`` (B,) and which rows are regular
        (the rank test of :func:`tangent`; bases of the other rows are meaningless).
    """
    m = jac.shape[1]
    q, r = np.linalg.qr(jac.transpose(0, 2, 1), mode="complete")
    phi = q[:, :, m:]
    size = np.abs(np.diagonal(r[:, :m, :m], axis1=1, axis2=2))
    regular = size.min(axis=1) > RANK_TOL * np.maximum(size.max(axis=1), scale)
    sign = np.empty(len(jac))
    square = np.ascontiguousarray(np.concatenate((jac, phi.transpose(0, 2, 1)), axis=1))
    det_signs(square, sign)  # compiled: see crossing_signs
    return phi, np.where(sign < 0, -1.0, 1.0), regular


# The stacked signs and cosines below are compiled (``_polytope.det_signs``,
# ``min_singular_values``): numpy.linalg's slogdet and svd cost 10-30 us a call on a wave's few
# dozen small matrices, several times their arithmetic, and only signs and the threshold test of
# Eq. (18) read the results.


def crossing_signs(phi_i: FloatArray, phi_j: FloatArray, sign_j: FloatArray) -> FloatArray:
    """:func:`crossing_sign` for stacks of bases (B, n, k) and signs (B,)."""
    det_sign = np.empty(len(phi_i))
    det_signs(np.matmul(phi_i.transpose(0, 2, 1), phi_j), det_sign)
    return np.where(det_sign < 0, -sign_j, sign_j)


def min_cosines(phi_i: FloatArray, phi_j: FloatArray) -> FloatArray:
    """:func:`min_cosine` for stacks of bases (B, n, k)."""
    cosines = np.empty(len(phi_i))
    min_singular_values(np.matmul(phi_i.transpose(0, 2, 1), phi_j), cosines)
    return cosines
