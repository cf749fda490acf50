"""What an atlas build takes and gives: settings, the frozen atlas, array type names."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sahgrasp.core.errors import AtlasError

__all__ = [
    "MIN_RADIUS_OVER_NEWTON_TOL",
    "STOP_REASONS",
    "Atlas",
    "AtlasSettings",
    "FloatArray",
    "Function",
    "IndexArray",
]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.int64]
Function = Callable[[FloatArray], FloatArray]

STOP_REASONS = ("complete", "max_charts", "stalled")
"""Why a build ended: every chart bounded (or at a box bound), ``max_charts`` charts exist, or
the start chart could not be expanded at all (every step from ``alpha = r`` down to
``min_step * r`` failed: ``r`` is too large or too small for the manifold)."""

MIN_RADIUS_OVER_NEWTON_TOL = 1e3
"""The chart radius must be at least this many times ``newton_tol``: a step shorter than that is
lost in the Newton projection's own error."""


@dataclass(frozen=True)
class AtlasSettings:
    """Parameters of the continuation.

    Attributes:
        radius: Chart radius ``r`` (the ball ``B_i`` in parameter space), in the units of ``x``.
        epsilon: Threshold of Eqs. (17)-(18), in (0, 1).
        max_charts: Stop once this many charts exist (the atlas is then not complete).
        newton_tol: Newton projection stops when ``|F(x)| <= newton_tol`` (Eq. (15)).
        newton_max_iter: Newton iterations before a projection counts as failed.
        min_step: Smallest step ``alpha`` as a fraction of ``r``; a vertex whose expansion fails at
            every step down to it is blocked (Algorithm 1, lines 9-12, with a floor).
        start_tol: Largest ``|F(x0)|`` accepted for the start point (it is projected first).
        batch: Charts expanded together in one wave (their first Newton projections, tangent
            spaces and Eq. (18) tests as stacked numpy calls); 1 expands one chart at a time
            (the one-chart engine). Waves change the order of expansion, hence the atlas
            slightly (chart counts within a few percent), not its coverage.
        progress: Draw a progress bar on stderr when :func:`build_atlas` gets no ``progress``
            callback (a front-end switch; the builder itself only calls the callback).
    """

    radius: float = 0.1
    epsilon: float = 0.1
    max_charts: int = 100_000
    newton_tol: float = 1e-10
    newton_max_iter: int = 20
    min_step: float = 0.1
    start_tol: float = 1e-6
    batch: int = 32
    progress: bool = False

    def __post_init__(self) -> None:
        checks = (
            (self.radius > 0 and np.isfinite(self.radius), "radius must be finite and > 0"),
            (
                self.radius >= MIN_RADIUS_OVER_NEWTON_TOL * self.newton_tol,
                f"radius must be >= {MIN_RADIUS_OVER_NEWTON_TOL:g} * newton_tol = "
                f"{MIN_RADIUS_OVER_NEWTON_TOL * self.newton_tol:g} (smaller steps are lost in "
                "the Newton tolerance)",
            ),
            (0 < self.epsilon < 1, "epsilon must lie in (0, 1)"),
            (self.max_charts >= 1, "max_charts must be >= 1"),
            (self.newton_tol > 0, "newton_tol must be > 0"),
            (self.newton_max_iter >= 1, "newton_max_iter must be >= 1"),
            (0 < self.min_step < 1, "min_step must lie in (0, 1)"),
            (self.start_tol >= self.newton_tol, "start_tol must be >= newton_tol"),
            (self.batch >= 1, "batch must be >= 1"),
        )
        for ok, message in checks:
            if not ok:
                raise AtlasError(f"invalid atlas settings: {message}; got {self}")


@dataclass(frozen=True)
class Atlas:
    """An atlas of the connected component of ``F(x) = 0`` that holds the start point.

    Attributes:
        centres: Chart centres ``x_i``, shape (N, n); ``centres[0]`` is the (projected) start.
        tangents: Orthonormal tangent bases ``Phi_i``, shape (N, n, k).
        radius: Chart radius ``r`` (every chart has the same one).
        epsilon: Threshold of Eqs. (17)-(18) the atlas was built with.
        edges: Pairs ``(i, j)``, ``i < j``, of neighbouring charts (``|x_i - x_j| < 2r`` and
            tangent spaces alike, see ``sahgrasp.atlas.builder``), shape (E, 2).
        parents: The chart each chart was expanded from (-1 for the first), shape (N,).
        boundary: Charts cut by a box bound or holding a blocked vertex, shape (N,).
        open: Charts that still had an expandable vertex when the build stopped, shape (N,).
        singular_points: Points where ``J`` drops rank or a branch is crossed, shape (S, n).
        newton_failures: Projections (Eq. (15)) that did not converge.
        rejections: Projections rejected by Eq. (17) or Eq. (18).
        bound_rejections: Projections that left the box bounds.
        build_seconds: Wall time of the build [s].
        stop_reason: Why the build ended, one of :data:`STOP_REASONS`: ``"max_charts"`` when the
            cap stopped it with charts still to expand, ``"stalled"`` when no chart could be
            added to the start chart (one chart, its vertices blocked).
    """

    centres: FloatArray
    tangents: FloatArray
    radius: float
    epsilon: float
    edges: IndexArray
    parents: IndexArray
    boundary: NDArray[np.bool_]
    open: NDArray[np.bool_]
    singular_points: FloatArray
    newton_failures: int
    rejections: int
    bound_rejections: int
    build_seconds: float
    stop_reason: str

    @property
    def n_charts(self) -> int:
        """Number of charts ``N``."""
        return int(self.centres.shape[0])

    @property
    def dim(self) -> int:
        """Manifold dimension ``k``."""
        return int(self.tangents.shape[2])

    @property
    def ambient_dim(self) -> int:
        """Ambient dimension ``n``."""
        return int(self.centres.shape[1])

    @property
    def complete(self) -> bool:
        """True when every chart is bounded or stopped at a box bound (no open frontier)."""
        return self.stop_reason == "complete"

    def neighbours(self, i: int) -> IndexArray:
        """Indices of the charts neighbouring chart ``i``, sorted."""
        e = self.edges
        return np.sort(np.concatenate((e[e[:, 0] == i, 1], e[e[:, 1] == i, 0])))
