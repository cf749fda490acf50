"""The continuation (Algorithm 1): expand charts from the start until the component is covered."""

from __future__ import annotations

import operator
import time
from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas.checks import check_bounds, start_point
from sahgrasp.atlas.model import Atlas, AtlasSettings, FloatArray, Function, IndexArray
from sahgrasp.atlas.neighbours import NeighbourIndex
from sahgrasp.atlas.polytope import CUT_TOL, Polytope
from sahgrasp.atlas.projection import Point, crossing_sign, min_cosine, project, regular_point
from sahgrasp.errors import AtlasError
from sahgrasp.progress import ProgressCallback, StderrProgress

__all__ = ["build_atlas"]

_SHRINK = 0.9  # Algorithm 1, line 11: alpha <- 0.9 alpha
_BISECTIONS = 40  # steps to locate a branch crossing along a chart's parameter ray
_PROGRESS_STAGE = "atlas charts"


@dataclass
class _Counters:
    newton_failures: int = 0
    rejections: int = 0
    bound_rejections: int = 0


@dataclass(slots=True)
class _Chart:
    """What the builder keeps of one chart besides its centre and basis (rows of its arrays).

    Attributes:
        sign: ``sign(det([J; Phi^T]))`` at the centre, to spot branch crossings.
        parent: The chart it was expanded from (-1 for the first).
        nbrs: Earlier charts neighbouring it (each edge is stored once, at its later chart).
        planes: Half-space normals ``a`` (``a . w <= b``) awaiting the polytope.
        offsets: Their offsets ``b``.
        poly: Its polytope, built from ``planes`` when the chart first reaches the queue's head.
        boundary: Cut by a box bound or holding a blocked vertex.
        queued: In the queue of charts to expand.
    """

    sign: float
    parent: int
    nbrs: IndexArray
    planes: list[list[float]]
    offsets: list[float]
    poly: Polytope | None = None
    boundary: bool = False
    queued: bool = False


class _Builder:
    """Mutable state of one atlas build.

    A new chart only records the planes of its neighbours; its polytope is built in one go when the
    chart reaches the head of the queue. From then on new neighbours cut it one plane at a time,
    as long as it can still be expanded (or holds blocked vertices that a cut could uncover).
    """

    def __init__(
        self,
        F: Function,
        J: Function,
        k: int,
        bounds: tuple[FloatArray, FloatArray],
        scale: float,
        settings: AtlasSettings,
    ) -> None:
        self.F, self.J, self.k, self.settings = F, J, k, settings
        self.lower, self.upper = bounds
        self.scale = scale  # size of J at the start, for the rank test of single equations
        self.bounded = bool((np.isfinite(self.lower) | np.isfinite(self.upper)).any())
        self.r = settings.radius
        self.tol = CUT_TOL * self.r
        n = self.lower.size
        self.X = np.empty((1024, n))
        self.PHI = np.empty((1024, n, k))
        self.charts: list[_Chart] = []  # chart i: centre X[i], basis PHI[i], the rest here
        self.singular: list[FloatArray] = []
        self.count = 0
        self.index = NeighbourIndex()
        self.queue: deque[int] = deque()
        self.counters = _Counters()

    # -- adding a chart ------------------------------------------------------------------------

    def _grow(self) -> None:
        for name in ("X", "PHI"):
            old = getattr(self, name)
            new = np.empty((2 * old.shape[0], *old.shape[1:]))
            new[: self.count] = old[: self.count]
            setattr(self, name, new)

    def add_chart(self, point: Point, parent: int) -> None:
        """Add a chart at ``point``; give it and each neighbour the other's plane (Fig. 6b)."""
        x, phi = point.x, point.phi
        if self.count == self.X.shape[0]:
            self._grow()
        j = self.count
        nbrs = self.index.query(self.X, j, x, 2 * self.r)
        bases = self.PHI[nbrs]
        similar = self._similar(bases, phi)
        if not similar.all():
            nbrs, bases = nbrs[similar], bases[similar]
        diff = x - self.X[nbrs]
        # Neighbour centres in each chart's parameters; the sphere |w| = r and the sphere of
        # radius r around u meet on the plane u . w = |u|^2 / 2. (matmul: einsum costs twice as
        # much per call on these small stacks.)
        U = -diff @ phi
        Uc = np.matmul(diff[:, None, :], bases)[:, 0]
        B = 0.5 * (U * U).sum(axis=1)
        Bc = 0.5 * (Uc * Uc).sum(axis=1)
        far = self.tol * self.r < B  # a neighbour straight along the normal gives no plane
        self.X[j], self.PHI[j] = x, phi
        self.charts.append(_Chart(point.sign, parent, nbrs, U[far].tolist(), B[far].tolist()))
        self.count = j + 1
        self.index.added(self.X, self.count)
        for c, a, b in zip(nbrs.tolist(), Uc.tolist(), Bc.tolist(), strict=True):
            if b > self.tol * self.r:
                self._give_plane(c, a, b)
        self._enqueue(j)

    def _similar(self, bases: FloatArray, phi: FloatArray) -> NDArray[np.bool_]:
        """Which of the tangent bases ``bases`` (q, n, k) are close enough to ``phi``.

        Eq. (18) lets a chart turn by ``theta = acos(1 - epsilon)`` from its parent at distance
        ``r``; neighbours (distance < 2r) turned by more than ``2 theta`` lie on another branch (a
        crossing, a cone's apex) and must not bound each other, so that the continuation passes
        through. ``|M|_F^2 - (k - 1)`` bounds the squared smallest singular value of M from below.
        """
        M = np.matmul(phi.T, bases)  # (q, k, k): phi^T Phi_c, the transpose has the same norms
        threshold = max(2.0 * (1.0 - self.settings.epsilon) ** 2 - 1.0, 0.0) ** 2  # cos(2 theta)^2
        unsure = (M * M).sum(axis=(1, 2)) - (self.k - 1) < threshold
        if unsure.any():
            sigma = np.linalg.svd(M[unsure], compute_uv=False)[:, -1]
            unsure[unsure] = sigma**2 < threshold
        return ~unsure

    def _give_plane(self, c: int, a: list[float], b: float) -> None:
        """Hand chart ``c`` the half-space ``a . w <= b`` of a new neighbour."""
        chart = self.charts[c]
        poly = chart.poly
        if poly is None:
            chart.planes.append(a)
            chart.offsets.append(b)
        elif (
            (chart.queued or chart.boundary)
            and 0.5 * b < poly.reach2  # the plane lies at distance |a| / 2 = sqrt(b / 2)
            and poly.cut(a, b, self.tol)
        ):
            self._enqueue(c)

    def _polytope(self, i: int) -> Polytope:
        """Chart ``i``'s polytope, built from its recorded planes on first use."""
        chart = self.charts[i]
        poly = chart.poly
        if poly is None:
            poly = Polytope.from_planes(self.k, self.r, chart.planes, chart.offsets)
            chart.poly, chart.planes, chart.offsets = poly, [], []
        return poly

    def _enqueue(self, c: int) -> None:
        chart = self.charts[c]
        if not chart.queued:
            poly = chart.poly
            if poly is None or poly.expandable(self.r**2) >= 0:
                chart.queued = True
                self.queue.append(c)

    # -- expanding -----------------------------------------------------------------------------

    def run(self, progress: ProgressCallback | None) -> None:
        """Expand charts until every one is bounded or ``max_charts`` is reached.

        ``progress`` hears of every new chart (``done`` charts of at most ``max_charts``).
        """
        r2, cap = self.r**2, self.settings.max_charts
        if progress is not None:
            progress(_PROGRESS_STAGE, self.count, cap)
        while self.queue and self.count < cap:
            i = self.queue[0]
            v = self._polytope(i).expandable(r2)
            if v < 0:
                self.queue.popleft()
                self.charts[i].queued = False
                continue
            if self.expand(i, v) and progress is not None:
                progress(_PROGRESS_STAGE, self.count, cap)

    def expand(self, i: int, v: int) -> bool:
        """Try to create a chart from vertex ``v`` of chart ``i`` (Algorithm 1, lines 7-13).

        Returns True when a chart was added. Otherwise either a box bound the candidates crossed
        cut ``v`` off, or ``v`` is blocked after every step down to ``min_step * r`` failed.
        """
        poly = self._polytope(i)
        vertex = poly.verts[v]
        direction = np.array(vertex) / np.sqrt(poly.norm2[v])
        alpha = self.r
        while alpha >= self.settings.min_step * self.r:
            x_tilde = self.X[i] + self.PHI[i] @ (alpha * direction)  # Eqs. (14), (16)
            x_j = self._project(i, x_tilde)
            if x_j is not None and self._outside(x_j):
                if self._cut_by_bounds(i, x_j, vertex):
                    return False
            elif x_j is not None:
                point = self._accept(i, x_j)
                if point is not None:
                    if crossing_sign(self.PHI[i], point.phi, point.sign) != self.charts[i].sign:
                        self._locate_crossing(i, direction, alpha)
                    self.add_chart(point, i)
                    return True
            alpha *= _SHRINK  # Algorithm 1, line 11
        poly.blocked[v] = True
        self.charts[i].boundary = True
        return False

    def _project(self, i: int, x_tilde: FloatArray) -> FloatArray | None:
        """Eq. (15) from ``x_tilde`` along chart ``i``; None if it fails or breaks Eq. (17)."""
        s, c = self.settings, self.counters
        x_j = project(self.F, self.J, x_tilde, self.PHI[i], s.newton_tol, s.newton_max_iter)
        if x_j is None:
            c.newton_failures += 1
            return None
        dx = x_j - x_tilde
        if dx @ dx > s.epsilon**2:  # Eq. (17)
            c.rejections += 1
            return None
        return x_j

    def _outside(self, x: FloatArray) -> bool:
        return self.bounded and bool((x < self.lower).any() or (x > self.upper).any())

    def _cut_by_bounds(self, i: int, x_j: FloatArray, vertex: tuple[float, ...]) -> bool:
        """Cut chart ``i`` by the bounds ``x_j`` violates, as ``lo <= x_i + Phi_i w <= hi``.

        Only bounds a candidate actually crossed are used, so a bound the manifold merely touches
        (a unit vector's component at 1) never cuts. Returns True when ``vertex`` was cut off.
        """
        self.counters.bound_rejections += 1
        self.charts[i].boundary = True
        x_i, phi = self.X[i], self.PHI[i]
        above, below = x_j > self.upper, x_j < self.lower
        planes = np.concatenate((phi[above], -phi[below])).tolist()
        offsets = np.concatenate((self.upper[above] - x_i[above], x_i[below] - self.lower[below]))
        poly = self._polytope(i)
        removed = False
        for a, b in zip(planes, np.maximum(offsets, self.tol).tolist(), strict=True):
            removed |= sum(map(operator.mul, a, vertex)) > b + self.tol
            poly.cut(a, b, self.tol)
        return removed

    def _accept(self, i: int, x_j: FloatArray) -> Point | None:
        """``x_j`` as a new centre, or None when ``J`` drops rank there or Eq. (18) fails."""
        point = regular_point(self.J, x_j, self.k, self.scale)
        if point is None:
            self._add_singular(x_j)
            self.counters.rejections += 1
            return None
        if min_cosine(self.PHI[i], point.phi) < 1.0 - self.settings.epsilon:  # Eq. (18)
            self.counters.rejections += 1
            return None
        return point

    def _locate_crossing(self, i: int, direction: FloatArray, alpha: float) -> None:
        """Bisect the ray of chart ``i`` for the sign change of ``det([J; Phi_i^T])``."""
        s = self.settings
        x_i, phi_i = self.X[i], self.PHI[i]
        lo, hi = 0.0, alpha
        best = x_i
        for _ in range(_BISECTIONS):
            mid = 0.5 * (lo + hi)
            x_tilde = x_i + phi_i @ (mid * direction)
            x = project(self.F, self.J, x_tilde, phi_i, s.newton_tol, s.newton_max_iter)
            if x is None or np.linalg.norm(x - x_tilde) > s.epsilon:  # Eq. (17)
                break
            best = x
            point = regular_point(self.J, x, self.k, self.scale)
            if point is None:
                break
            if crossing_sign(phi_i, point.phi, point.sign) == self.charts[i].sign:
                lo = mid
            else:
                hi = mid
        self._add_singular(best)

    def _add_singular(self, x: FloatArray) -> None:
        """Record a singular point unless one already lies within ``r`` of it."""
        if all(np.linalg.norm(p - x) >= self.r for p in self.singular):
            self.singular.append(x.copy())

    def result(self, seconds: float) -> Atlas:
        """Freeze the state into an :class:`Atlas`."""
        n, N = self.X.shape[1], self.count
        charts = self.charts
        sizes = [len(c.nbrs) for c in charts]
        nbrs = np.concatenate([c.nbrs for c in charts])
        edges = np.stack((nbrs, np.repeat(np.arange(N), sizes)), axis=1)
        still_open = np.array([c.queued for c in charts], dtype=bool)
        return Atlas(
            centres=self.X[:N].copy(),
            tangents=self.PHI[:N].copy(),
            radius=self.r,
            epsilon=self.settings.epsilon,
            edges=edges.astype(np.int64),
            parents=np.array([c.parent for c in charts], dtype=np.int64),
            boundary=np.array([c.boundary for c in charts], dtype=bool),
            open=still_open,
            singular_points=np.array(self.singular).reshape(-1, n),
            newton_failures=self.counters.newton_failures,
            rejections=self.counters.rejections,
            bound_rejections=self.counters.bound_rejections,
            build_seconds=seconds,
            stop_reason="max_charts" if still_open.any() else "complete",
        )


def build_atlas(
    F: Function,
    J: Function,
    x0: ArrayLike,
    k: int,
    settings: AtlasSettings | None = None,
    lower: ArrayLike | None = None,
    upper: ArrayLike | None = None,
    progress: ProgressCallback | None = None,
) -> Atlas:
    """Cover the connected component of ``F(x) = 0`` through ``x0`` with charts (Section IV).

    Args:
        F: Residual ``R^n -> R^(n-k)``; must accept and return float arrays.
        J: Its Jacobian ``R^n -> R^((n-k) x n)``.
        x0: A point on the manifold (``|F(x0)| <= settings.start_tol``), shape (n,).
        k: Manifold dimension, ``1 <= k < n``; must equal ``n - rank(J(x0))``.
        settings: Continuation parameters (radius ``r``, ``epsilon``, caps); defaults if None.
        lower: Lower box bound on ``x`` (``-inf`` for none), shape (n,).
        upper: Upper box bound on ``x`` (``+inf`` for none), shape (n,).
        progress: Called after every new chart as ``progress("atlas charts", charts,
            max_charts)``; with None, ``settings.progress`` draws a bar on stderr.

    Returns:
        The atlas; when ``max_charts`` stopped the build, ``atlas.stop_reason`` is
        ``"max_charts"`` and ``atlas.complete`` is False.

    Raises:
        AtlasError: Shapes of ``F``/``J`` disagree with ``n`` and ``k``, ``x0`` is off the manifold,
            singular or outside the bounds, or the settings are invalid.
    """
    start_time = time.perf_counter()
    settings = settings or AtlasSettings()
    point = start_point(F, J, x0, k, settings)
    lo = check_bounds(lower, point.x.size, -np.inf, "lower")
    hi = check_bounds(upper, point.x.size, np.inf, "upper")
    if (point.x < lo).any() or (point.x > hi).any():
        raise AtlasError("x0 lies outside the box [lower, upper]; the start must lie within it")
    scale = float(np.sqrt(np.einsum("ij,ij->i", J(point.x), J(point.x))).max())
    builder = _Builder(F, J, k, (lo, hi), scale, settings)
    builder.add_chart(point, -1)
    if progress is None and settings.progress:
        with StderrProgress() as bar:
            builder.run(bar)
    else:
        builder.run(progress)
    return builder.result(time.perf_counter() - start_time)
