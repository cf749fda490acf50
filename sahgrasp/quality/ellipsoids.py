"""Grasp quality from the manipulability ellipsoid (Bicchi & Prattichizzo 2000, ref. [1]).

At a feasible grasp ``x`` let ``T`` (n x t) be a basis of the tangent space of the feasible-grasp
manifold F, so that every feasible motion is ``dx = T tau``. The actuated joint velocities are
``qdot = A tau`` with ``A = J_a T`` and the object velocity is ``nu = B tau`` with ``B = J_o T``.
The manipulability ellipsoid is the set of object velocities reachable with a unit-norm actuated
velocity compatible with the constraints, ``{B tau : |A tau| <= 1}``. With the thin SVD
``A = U S V^T`` it is the image of the unit ball by ``M = B V S^-1``, whose singular values are
the ellipsoid's semi-axes. The atlas paper (Section V, Fig. 9) optimises three indices of it: the
inverse condition number, the volume and the smallest semi-axis, and calls a grasp singular when
the index falls below 1e-3, 1e-4 and 1e-3 respectively. Indices are registered objects (name,
function, threshold, description: :mod:`sahgrasp.quality.indices`, whose names this module
re-exports); :func:`register_index` adds one.

Everything here is vectorised over leading axes (one entry per chart). ``evaluate_index``
evaluates any index, built-in or user-supplied, at the centres of an atlas and picks the best and
worst charts among the candidates; ``principal_projection`` gives the chart centres' coordinates on
their principal axes, to plot them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas._quality import orthogonal_tail
from sahgrasp.atlas._quality import semi_axes as compiled_semi_axes
from sahgrasp.core.errors import QualityError
from sahgrasp.quality.indices import (
    PAPER_INDICES,
    QUALITY_INDICES,
    SINGULAR_THRESHOLDS,
    QualityIndex,
    register_index,
)

__all__ = [
    "INDICES",
    "QUALITY_INDICES",
    "SINGULAR_THRESHOLDS",
    "ChartCentres",
    "IndexEvaluation",
    "Manipulability",
    "QualityIndex",
    "ellipsoid_indices",
    "evaluate_index",
    "full_rank_null_space",
    "manipulability",
    "null_space",
    "principal_projection",
    "register_index",
    "semi_axes",
]

FloatArray = NDArray[np.float64]

INDICES = PAPER_INDICES
"""Names of the atlas paper's indices, in the order of Fig. 9 (a)-(c); every registered index:
:data:`QUALITY_INDICES` (and its thresholds, :data:`SINGULAR_THRESHOLDS`)."""

_RANK_TOL = 1e-12  # relative singular value below which a matrix counts as rank deficient


@dataclass(frozen=True)
class Manipulability:
    """Manipulability ellipsoids of one grasp or of a batch (leading axes ``...``).

    Attributes:
        semi_axes: Semi-axis lengths, decreasing, shape (..., o); zeros where the hand cannot move
            the object at all in some direction. All zero when the actuated joints do not determine
            the grasp motion (``A`` rank deficient): the object then moves with the joints locked.
        inverse_condition: Smallest over largest semi-axis, shape (...).
        volume: Product of the semi-axes (the ellipsoid volume over that of the unit ball), (...).
        min_semiaxis: Smallest semi-axis, shape (...).
    """

    semi_axes: FloatArray
    inverse_condition: FloatArray
    volume: FloatArray
    min_semiaxis: FloatArray

    def index(self, name: str) -> FloatArray:
        """The values of the registered index ``name`` (:data:`QUALITY_INDICES`).

        Raises:
            QualityError: ``name`` is not registered (the message lists the valid names).
        """
        values = QUALITY_INDICES.lookup(name).function(self)
        return np.asarray(values, dtype=np.float64)

    def singular(self, name: str) -> NDArray[np.bool_]:
        """True where index ``name`` is below its singularity threshold."""
        return self.index(name) < QUALITY_INDICES.lookup(name).singular_below


def null_space(jac: ArrayLike, dim: int) -> FloatArray:
    """Orthonormal bases (..., n, dim) of the null spaces of a batch of Jacobians (..., m, n).

    The last ``dim`` right singular vectors: the tangent space of ``F = 0`` when ``J`` has rank
    ``n - dim``.
    """
    vt = np.linalg.svd(np.asarray(jac, dtype=np.float64), full_matrices=True)[2]
    return np.swapaxes(vt[..., vt.shape[-1] - dim :, :], -1, -2)


def full_rank_null_space(jac: ArrayLike) -> FloatArray:
    """Orthonormal bases (..., n, n - m) of the null spaces of full-row-rank Jacobians (..., m, n).

    The last ``n - m`` columns of Q in the Householder QR ``J^T = Q R``: the same spaces as
    :func:`null_space` when every ``J`` has rank ``m`` (a regular point, such as a chart centre),
    at a small part of the SVD's cost on a stack of chart centres. numpy factorises; only the
    columns wanted are then formed from the reflectors (compiled,
    ``atlas._quality.orthogonal_tail``: numpy would form all of Q, which took most of the time;
    docs/results.md, "The atlas engine and the atlas paper's experiments").
    A rank-deficient ``J`` gives a meaningless basis: use :func:`null_space` there.
    """
    jac = np.asarray(jac, dtype=np.float64)
    m, n = jac.shape[-2:]
    reflectors, tau = np.linalg.qr(np.swapaxes(jac, -1, -2), mode="raw")  # (..., m, n), (..., m)
    basis = np.empty((*jac.shape[:-2], n, n - m))
    orthogonal_tail(
        np.ascontiguousarray(reflectors).reshape(-1, m, n),
        np.ascontiguousarray(tau).reshape(-1, m),
        basis.reshape(-1, n, n - m),
    )
    return basis


def semi_axes(actuated: ArrayLike, obj: ArrayLike) -> FloatArray:
    """Semi-axes of the manipulability ellipsoids ``{B tau : |A tau| <= 1}``.

    Args:
        actuated: ``A = J_a T``, actuated joint velocity per tangent coordinate, (..., a, t).
        obj: ``B = J_o T``, object velocity per tangent coordinate, (..., o, t).

    Returns:
        Semi-axis lengths, decreasing, (..., o); all zero where ``A`` is rank deficient.
    """
    A, B = np.asarray(actuated, dtype=np.float64), np.asarray(obj, dtype=np.float64)
    batch = np.broadcast_shapes(A.shape[:-2], B.shape[:-2])
    (a, t), o = A.shape[-2:], B.shape[-2]
    A = np.ascontiguousarray(np.broadcast_to(A, (*batch, a, t))).reshape(-1, a, t)
    B = np.ascontiguousarray(np.broadcast_to(B, (*batch, o, t))).reshape(-1, o, t)
    axes = np.empty((*batch, o))
    # Compiled (atlas._quality.semi_axes): M = B V S^-1 from A = U S V^T and the singular values
    # of M, by one-sided Jacobi per grasp; numpy's SVDs cost about 4 us a small matrix.
    compiled_semi_axes(A, B, axes.reshape(-1, o), _RANK_TOL)
    return axes


def ellipsoid_indices(actuated: ArrayLike, obj: ArrayLike) -> Manipulability:
    """The three indices of the manipulability ellipsoids; arguments as :func:`semi_axes`."""
    axes = semi_axes(actuated, obj)
    largest, smallest = axes[..., 0], axes[..., -1]
    with np.errstate(invalid="ignore", divide="ignore"):
        inverse_condition = np.where(largest > 0, smallest / largest, 0.0)
    return Manipulability(
        semi_axes=axes,
        inverse_condition=inverse_condition,
        volume=np.prod(axes, axis=-1),
        min_semiaxis=smallest,
    )


def _velocity_map(rows_or_matrix: ArrayLike, tangent: FloatArray) -> FloatArray:
    """``tangent`` rows (integer indices) or ``matrix @ tangent`` (a float (..., p, n) matrix)."""
    m = np.asarray(rows_or_matrix)
    if np.issubdtype(m.dtype, np.integer):
        if m.ndim != 1:
            raise QualityError(f"coordinate rows must be a 1-D integer array, got shape {m.shape}")
        return tangent[..., m, :]
    return np.asarray(m, dtype=np.float64) @ tangent


def manipulability(tangent: ArrayLike, actuated: ArrayLike, obj: ArrayLike) -> Manipulability:
    """Manipulability ellipsoid of grasps from their tangent spaces.

    Args:
        tangent: Basis ``T`` of the tangent space of the feasible-grasp manifold, (..., n, t).
        actuated: Rows of ``x`` that are actuated joint coordinates (integer array), or the
            Jacobian ``J_a`` (..., a, n) mapping ``dx`` to actuated joint velocities.
        obj: Rows of ``x`` that are object coordinates (integer array), or the Jacobian ``J_o``
            (..., o, n) mapping ``dx`` to the object velocity.

    Returns:
        Semi-axes and the three indices, with the batch shape of ``tangent``.
    """
    T = np.asarray(tangent, dtype=np.float64)
    return ellipsoid_indices(_velocity_map(actuated, T), _velocity_map(obj, T))


class ChartCentres(Protocol):
    """What :func:`evaluate_index` needs of an atlas (:class:`sahgrasp.atlas.Atlas` has it)."""

    @property
    def centres(self) -> FloatArray:
        """Chart centres, (N, n)."""
        ...


@dataclass(frozen=True)
class IndexEvaluation:
    """A quality index evaluated at every chart centre of an atlas.

    Attributes:
        values: Index value per chart, shape (N,); NaN where the index is undefined.
        best: Candidate chart with the largest value.
        worst: Candidate chart with the smallest value.
        best_overall: Chart with the largest value over all charts (``best`` when that one is a
            candidate).
        seconds: Wall time of the evaluation [s].
    """

    values: FloatArray
    best: int
    worst: int
    best_overall: int
    seconds: float


def evaluate_index(
    atlas: ChartCentres,
    index_fn: Callable[[FloatArray], ArrayLike],
    vectorised: bool = True,
    candidates: ArrayLike | None = None,
) -> IndexEvaluation:
    """Evaluate a quality index at the centre of every chart (Algorithm 1, lines 14-21).

    Args:
        atlas: The atlas whose chart centres are the candidate grasps.
        index_fn: With ``vectorised``, maps the centres (N, n) to N values; otherwise maps one
            centre (n,) to one value. Larger is better.
        vectorised: Whether ``index_fn`` takes all centres at once.
        candidates: Per chart, whether it may be the best or worst (e.g. collision-free),
            (N,) booleans; all charts if None.

    Returns:
        The values with the best (largest) and worst (smallest) candidate chart.

    Raises:
        QualityError: ``index_fn`` returned the wrong number of values, or only NaN, or no
            candidate has a value.
    """
    start = time.perf_counter()
    if vectorised:
        values = np.asarray(index_fn(atlas.centres), dtype=np.float64).reshape(-1)
    else:
        values = np.array([float(np.asarray(index_fn(x))) for x in atlas.centres])
    charts = len(atlas.centres)
    if values.shape != (charts,):
        raise QualityError(f"index_fn gave {values.size} values for {charts} charts")
    if np.isnan(values).all():
        raise QualityError("index_fn gave NaN at every chart")
    allowed = np.ones(charts, dtype=bool) if candidates is None else np.asarray(candidates, bool)
    if allowed.shape != (charts,):
        raise QualityError(f"candidates must be {charts} booleans, got shape {allowed.shape}")
    scored = np.flatnonzero(allowed & ~np.isnan(values))
    if not scored.size:
        raise QualityError(f"no candidate chart has an index value ({allowed.sum()} candidates)")
    return IndexEvaluation(
        values=values,
        best=int(scored[np.argmax(values[scored])]),
        worst=int(scored[np.argmin(values[scored])]),
        best_overall=int(np.nanargmax(values)),
        seconds=time.perf_counter() - start,
    )


def principal_projection(points: ArrayLike, dims: int = 2) -> FloatArray:
    """Coordinates (N, dims) of points (N, n) on their first ``dims`` principal axes, centred.

    How chart centres of a high-dimensional ``x`` are plotted (Figs. 9-10 of the atlas paper).
    """
    centred = np.asarray(points, dtype=np.float64)
    centred = centred - centred.mean(axis=0)
    vt = np.linalg.svd(centred, full_matrices=False)[2]
    projected: FloatArray = centred @ vt[:dims].T
    return projected
