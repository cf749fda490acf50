"""Higher-dimensional continuation: an atlas of an implicitly defined k-manifold F(x) = 0.

Henderson's method as used in Section IV of the atlas paper (atlas-grasp-optimization.md). A chart
``C_i`` has a centre ``x_i`` on the manifold and an orthonormal basis ``Phi_i`` (n x k) of the
tangent space there. A point ``u`` of the chart's parameter space maps to ``x_i + Phi_i u``
(Eq. (14)) and then onto the manifold by the orthogonal projection of Eq. (15). The domain of a
chart is a polytope ``P_i`` in parameter space: a cube enclosing the ball ``B_i`` of radius ``r``,
cut by one half-space per neighbouring chart (the plane through the intersection of ``B_i`` and
the ball ``B_j^i`` of radius ``r`` around the neighbour's projected centre). A vertex of ``P_i``
outside ``B_i`` is expanded into a new chart (Eqs. (16)-(18)); when every vertex lies inside its
ball the chart is bounded and, once all charts are, the connected component of the start point is
covered.

Box bounds on ``x`` (joint limits, patch parameter ranges): a new centre must lie inside the box;
when a candidate crosses a bound, the bound's linearisation cuts the chart's polytope, and a
vertex whose expansion fails down to the smallest step is blocked (marked as boundary, never
expanded again). A drop of the rank of ``J`` at a candidate centre, or a sign
change of ``det([J; Phi_i^T])`` between a chart and its child (a branch crossing), is reported as a
singular point; neither stops the continuation.

This module knows nothing of hands: it is tested on spheres, tori and curves.
"""

from __future__ import annotations

import functools
import itertools
import operator
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dgeqrf as _dgeqrf
from scipy.linalg.lapack import dgesdd as _dgesdd
from scipy.linalg.lapack import dgesv as _dgesv
from scipy.linalg.lapack import dgetrf as _dgetrf
from scipy.linalg.lapack import dorgqr as _dorgqr
from scipy.spatial import ConvexHull, QhullError, cKDTree

from sahgrasp.errors import AtlasError
from sahgrasp.progress import ProgressCallback, StderrProgress

__all__ = ["STOP_REASONS", "Atlas", "AtlasSettings", "build_atlas", "project"]

FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.int64]
Function = Callable[[FloatArray], FloatArray]

_SHRINK = 0.9  # Algorithm 1, line 11: alpha <- 0.9 alpha
_MASK_BITS = 62  # facets a Qhull-built polytope may have (one bit each of an int64 mask)
_CUT_TOL = 1e-9  # a vertex closer than this (times r) to a plane lies on it
_RANK_TOL = 1e-8  # relative size of the smallest R diagonal of qr(J^T) below which J drops rank
_BISECTIONS = 40  # steps to locate a branch crossing along a chart's parameter ray
_PROGRESS_STAGE = "atlas charts"

STOP_REASONS = ("complete", "max_charts")
"""Why a build ended: every chart bounded (or at a box bound), or ``max_charts`` charts exist."""


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
    progress: bool = False

    def __post_init__(self) -> None:
        checks = (
            (self.radius > 0 and np.isfinite(self.radius), "radius must be finite and > 0"),
            (0 < self.epsilon < 1, "epsilon must lie in (0, 1)"),
            (self.max_charts >= 1, "max_charts must be >= 1"),
            (self.newton_tol > 0, "newton_tol must be > 0"),
            (self.newton_max_iter >= 1, "newton_max_iter must be >= 1"),
            (0 < self.min_step < 1, "min_step must lie in (0, 1)"),
            (self.start_tol >= self.newton_tol, "start_tol must be >= newton_tol"),
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
            tangent spaces alike, see ``_Builder._similar``), shape (E, 2).
        parents: The chart each chart was expanded from (-1 for the first), shape (N,).
        boundary: Charts cut by a box bound or holding a blocked vertex, shape (N,).
        open: Charts that still had an expandable vertex when the build stopped, shape (N,).
        singular_points: Points where ``J`` drops rank or a branch is crossed, shape (S, n).
        newton_failures: Projections (Eq. (15)) that did not converge.
        rejections: Projections rejected by Eq. (17) or Eq. (18).
        bound_rejections: Projections that left the box bounds.
        build_seconds: Wall time of the build [s].
        stop_reason: Why the build ended, one of :data:`STOP_REASONS`: ``"max_charts"`` when the
            cap stopped it with charts still to expand.
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
        return not bool(self.open.any())

    def neighbours(self, i: int) -> IndexArray:
        """Indices of the charts neighbouring chart ``i``, sorted."""
        e = self.edges
        return np.sort(np.concatenate((e[e[:, 0] == i, 1], e[e[:, 1] == i, 0])))


# --------------------------------------------------------------------------------------------
# Polytopes: vertices plus, per vertex, a bit mask of the faces through it.
# --------------------------------------------------------------------------------------------


@functools.cache
def _cube_normals(k: int) -> FloatArray:
    """Outer normals of the faces of a k-cube, ``+e_d`` then ``-e_d`` interleaved."""
    return np.concatenate((np.eye(k), -np.eye(k)), axis=1).reshape(2 * k, k)


def _chain(points: list[list[float]], order: list[int]) -> list[int]:
    """One half of Andrew's monotone-chain convex hull: indices turning strictly left."""
    out: list[int] = []
    for i in order:
        x, y = points[i]
        while len(out) >= 2:
            (ax, ay), (bx, by) = points[out[-2]], points[out[-1]]
            if (bx - ax) * (y - ay) - (by - ay) * (x - ax) > 0:
                break
            out.pop()
        out.append(i)
    return out


class _Polytope:
    """Convex polytope in a chart's parameter space, vertex/face incidence as integer bit masks.

    Plain Python lists: a polytope has a handful of vertices (k <= 3), where per-call numpy overhead
    would dominate the incremental cuts.
    """

    __slots__ = ("blocked", "masks", "norm2", "reach2", "verts")

    def __init__(self, verts: list[tuple[float, ...]], masks: list[int]) -> None:
        self.verts = verts
        self.masks = masks
        self.blocked = [False] * len(verts)
        self.norm2 = [sum(c * c for c in v) for v in verts]
        self.reach2 = max(self.norm2)  # squared distance of the farthest vertex

    @classmethod
    def cube(cls, k: int, r: float) -> _Polytope:
        """The k-cube ``[-r, r]^k`` enclosing the ball ``B_i`` (Fig. 6a); face 2d+s is x_d = -+r."""
        verts = list(itertools.product((-r, r), repeat=k))
        masks = [sum(1 << (2 * d + (c < 0)) for d, c in enumerate(v)) for v in verts]
        return cls(verts, masks)

    @classmethod
    def from_planes(
        cls, k: int, r: float, planes: list[list[float]], offsets: list[float]
    ) -> _Polytope:
        """The cube ``[-r, r]^k`` cut by every half-space ``planes[h] . w <= offsets[h] (> 0)``.

        For k >= 2 all cuts are made at once through polar duality: the polytope
        ``{w : p_h . w <= 1}``, ``p_h = planes[h] / offsets[h]``, has one vertex per facet of the
        convex hull of the ``p_h``. k = 1, or a degenerate hull, falls back to one cut per plane.
        """
        tol = _CUT_TOL * r
        if k == 2:
            inv = 1.0 / r
            cube = [[inv, 0.0], [-inv, 0.0], [0.0, inv], [0.0, -inv]]
            return cls._from_dual_polygon(
                cube + [[a / b, c / b] for (a, c), b in zip(planes, offsets, strict=True)]
            )
        if k >= 3:
            A = np.concatenate((_cube_normals(k), np.reshape(planes, (-1, k))))
            b = np.concatenate((np.full(2 * k, r), offsets))
            poly = cls._from_qhull(A / b[:, None], tol)
            if poly is not None:
                return poly
        poly = cls.cube(k, r)
        for a, off in zip(planes, offsets, strict=True):
            poly.cut(list(a), off, tol)
        return poly

    @classmethod
    def _from_qhull(cls, dual: FloatArray, tol: float) -> _Polytope | None:
        """Polytope ``{w : dual @ w <= 1}`` from Qhull's hull of ``dual``; None if degenerate."""
        try:
            hull = ConvexHull(dual)
        except QhullError:
            return None
        faces = hull.vertices  # the planes that are facets of the polytope
        if len(faces) > _MASK_BITS:
            return None
        eq = hull.equations  # n . p + c = 0 on a hull facet: the polytope vertex is -n / c
        verts = eq[:, :-1] / -eq[:, -1:]
        facet_dual = dual[faces]  # distance of v to plane h: |p_h . v - 1| / |p_h|
        tight = np.abs(verts @ facet_dual.T - 1.0) <= tol * np.linalg.norm(facet_dual, axis=1)
        masks = tight @ np.left_shift(1, np.arange(len(faces), dtype=np.int64))
        return cls(list(map(tuple, verts.tolist())), masks.tolist())

    @classmethod
    def _from_dual_polygon(cls, dual: list[list[float]]) -> _Polytope:
        """Polygon ``{w : p . w <= 1 for p in dual}``: consecutive dual hull points give vertices.

        Plain Python (monotone chain): for a dozen points it is several times faster than Qhull.
        """
        order = sorted(range(len(dual)), key=dual.__getitem__)
        lower, upper = _chain(dual, order), _chain(dual, order[::-1])
        hull = lower[:-1] + upper[:-1]  # counter-clockwise around the origin
        verts: list[tuple[float, ...]] = []
        masks: list[int] = []
        for s, t in zip(hull, hull[1:] + hull[:1], strict=True):
            (px, py), (qx, qy) = dual[s], dual[t]
            det = px * qy - py * qx  # the vertex solves p . v = q . v = 1
            verts.append(((qy - py) / det, (px - qx) / det))
            masks.append((1 << s) | (1 << t))
        return cls(verts, masks)

    def expandable(self, r2: float) -> int:
        """Index of the nearest unblocked vertex not inside the ball of squared radius ``r2``.

        The nearest (rather than the farthest) exterior vertex gives ~Vol/r^k charts on spheres.
        """
        best, v = np.inf, -1
        for i, (n2, blocked) in enumerate(zip(self.norm2, self.blocked, strict=True)):
            if r2 <= n2 < best and not blocked:
                best, v = n2, i
        return v

    def cut(self, a: list[float], b: float, tol: float) -> bool:
        """Intersect with the half-space ``a . w <= b``; return True when something was removed.

        Vertices on the plane (within ``tol``) gain the new face; every edge from a kept vertex to a
        removed one (two vertices sharing at least k-1 faces) yields a new vertex on the plane.
        """
        verts, masks = self.verts, self.masks
        d = [sum(map(operator.mul, a, v)) - b for v in verts]
        if max(d) <= tol:
            return False
        out = [i for i, di in enumerate(d) if di > tol]
        keep = [i for i, di in enumerate(d) if di <= tol]
        used = 0
        for i in keep:
            used |= masks[i]
        bit = ~used & (used + 1)  # lowest face bit no kept vertex uses
        new_verts = [verts[i] for i in keep]
        new_masks = [masks[i] | bit if d[i] >= -tol else masks[i] for i in keep]
        blocked = [self.blocked[i] for i in keep]
        norm2 = [self.norm2[i] for i in keep]
        k1 = len(a) - 1
        for i in keep:
            di, mi, vi = d[i], masks[i], verts[i]
            if di >= -tol:
                continue
            for o in out:
                shared = mi & masks[o]
                if shared.bit_count() >= k1:
                    t = di / (di - d[o])
                    v = tuple(p + t * (q - p) for p, q in zip(vi, verts[o], strict=True))
                    new_verts.append(v)
                    new_masks.append(shared | bit)
                    blocked.append(False)
                    norm2.append(sum(c * c for c in v))
        self.verts, self.masks, self.blocked, self.norm2 = new_verts, new_masks, blocked, norm2
        self.reach2 = max(norm2)
        return True


# --------------------------------------------------------------------------------------------
# Local geometry: Newton projection (Eq. (15)) and tangent spaces.
# --------------------------------------------------------------------------------------------


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


def _tangent(jac: FloatArray, k: int, scale: float = 0.0) -> tuple[FloatArray, float] | None:
    """Null-space basis ``phi`` (n x k) of ``jac`` and the sign of ``det([J; phi^T])``.

    From ``J^T = Q R`` (Householder): ``phi`` is the last k columns of Q, and
    ``det([J; phi^T]) = det(R_1) det(Q)`` with ``det(Q) = (-1)^(number of reflections)``.
    Returns None when ``J`` drops rank (a singular point): a diagonal entry of R below
    ``_RANK_TOL`` times the largest one, or times ``scale`` (that of the start point), whichever is
    larger; the latter catches ``J -> 0`` when F has a single equation.
    """
    m, n = jac.shape
    qr, tau, _, _ = _dgeqrf(jac.T)
    diag = qr.diagonal().tolist()  # plain Python: m is small and numpy calls cost more
    size = [abs(d) for d in diag]
    if min(size) <= _RANK_TOL * max(*size, scale):
        return None
    full = np.empty((n, n))
    full[:, :m] = qr
    q = _dorgqr(full, tau)[0]
    flips = sum(d < 0 for d in diag) + sum(t != 0 for t in tau.tolist())
    return q[:, m:], -1.0 if flips % 2 else 1.0


def _crossing_sign(phi_i: FloatArray, phi_j: FloatArray, sign_j: float) -> float:
    """Sign of ``det([J(x_j); phi_i^T])`` from chart j's own sign.

    ``phi_i^T`` minus its component along the rows of ``J`` is ``(phi_i^T phi_j) phi_j^T``, so
    ``det([J; phi_i^T]) = det(phi_i^T phi_j) det([J; phi_j^T])``. A change of this sign between
    ``x_i`` and ``x_j`` means the path crossed a point where ``J`` or the chart degenerates.
    """
    lu, piv, _ = _dgetrf(phi_i.T @ phi_j)
    flips = sum(d < 0 for d in lu.diagonal().tolist())
    flips += sum(p != row for row, p in enumerate(piv.tolist()))
    return -sign_j if flips % 2 else sign_j


def _min_cosine(phi_i: FloatArray, phi_j: FloatArray) -> float:
    """Smallest singular value of ``phi_i^T phi_j``: the norm of Eq. (18)."""
    return float(_dgesdd(phi_i.T @ phi_j, compute_uv=0)[1][-1])


class _Point(NamedTuple):
    """A regular point of the manifold with its tangent basis and ``sign(det([J; phi^T]))``."""

    x: FloatArray
    phi: FloatArray
    sign: float


def _regular_point(J: Function, x: FloatArray, k: int, scale: float = 0.0) -> _Point | None:
    """``x`` with its tangent space, or None when ``J(x)`` drops rank (see :func:`_tangent`)."""
    tangent = _tangent(J(x), k, scale)
    return None if tangent is None else _Point(x, *tangent)


# --------------------------------------------------------------------------------------------
# Neighbour search: a KD-tree rebuilt in batches plus a brute-force scan of recent charts.
# --------------------------------------------------------------------------------------------


class _NeighbourIndex:
    """Ball queries over a growing point set, without quadratic cost."""

    __slots__ = ("_n_tree", "_tree")

    def __init__(self) -> None:
        self._tree: cKDTree | None = None
        self._n_tree = 0

    def query(self, points: FloatArray, count: int, x: FloatArray, radius: float) -> IndexArray:
        """Indices ``< count`` of ``points`` closer than ``radius`` to ``x``."""
        pending = points[self._n_tree : count] - x
        near = self._n_tree + np.flatnonzero(np.einsum("ij,ij->i", pending, pending) < radius**2)
        if self._tree is None:
            return near
        found = np.asarray(self._tree.query_ball_point(x, radius, return_sorted=False), np.int64)
        return np.concatenate((found, near))

    def added(self, points: FloatArray, count: int) -> None:
        """Note that ``count`` points exist; rebuild the tree when the unindexed tail is long."""
        if count - self._n_tree > max(32, count // 16):
            self._tree = cKDTree(points[:count])
            self._n_tree = count


# --------------------------------------------------------------------------------------------
# The continuation itself.
# --------------------------------------------------------------------------------------------


@dataclass
class _Counters:
    newton_failures: int = 0
    rejections: int = 0
    bound_rejections: int = 0


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
        self.tol = _CUT_TOL * self.r
        n = self.lower.size
        self.X = np.empty((1024, n))
        self.PHI = np.empty((1024, n, k))
        self.polys: list[_Polytope | None] = []
        self.planes: list[list[list[float]]] = []  # planes a . w <= b awaiting the polytope
        self.offsets: list[list[float]] = []
        self.signs: list[float] = []
        self.parents: list[int] = []
        self.boundary: list[bool] = []
        self.nbrs: list[IndexArray] = []  # earlier charts neighbouring each chart
        self.singular: list[FloatArray] = []
        self.count = 0
        self.index = _NeighbourIndex()
        self.queue: deque[int] = deque()
        self.queued: list[bool] = []
        self.counters = _Counters()

    # -- adding a chart ------------------------------------------------------------------------

    def _grow(self) -> None:
        for name in ("X", "PHI"):
            old = getattr(self, name)
            new = np.empty((2 * old.shape[0], *old.shape[1:]))
            new[: self.count] = old[: self.count]
            setattr(self, name, new)

    def add_chart(self, point: _Point, parent: int) -> None:
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
        diff = self.X[nbrs] - x
        # Neighbour centres in each chart's parameters; the sphere |w| = r and the sphere of
        # radius r around u meet on the plane u . w = |u|^2 / 2.
        U = diff @ phi
        Uc = np.einsum("qnk,qn->qk", bases, -diff)
        B = 0.5 * np.einsum("ij,ij->i", U, U)
        Bc = 0.5 * np.einsum("ij,ij->i", Uc, Uc)
        far = self.tol * self.r < B  # a neighbour straight along the normal gives no plane
        self.X[j], self.PHI[j] = x, phi
        self.polys.append(None)
        self.planes.append(U[far].tolist())
        self.offsets.append(B[far].tolist())
        self.signs.append(point.sign)
        self.parents.append(parent)
        self.boundary.append(False)
        self.queued.append(False)
        self.nbrs.append(nbrs)
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
        M = np.einsum("qnk,nl->qkl", bases, phi)
        threshold = max(2.0 * (1.0 - self.settings.epsilon) ** 2 - 1.0, 0.0) ** 2  # cos(2 theta)^2
        unsure = np.einsum("qkl,qkl->q", M, M) - (self.k - 1) < threshold
        if unsure.any():
            sigma = np.linalg.svd(M[unsure], compute_uv=False)[:, -1]
            unsure[unsure] = sigma**2 < threshold
        return ~unsure

    def _give_plane(self, c: int, a: list[float], b: float) -> None:
        """Hand chart ``c`` the half-space ``a . w <= b`` of a new neighbour."""
        poly = self.polys[c]
        if poly is None:
            self.planes[c].append(a)
            self.offsets[c].append(b)
        elif (
            (self.queued[c] or self.boundary[c])
            and 0.5 * b < poly.reach2  # the plane lies at distance |a| / 2 = sqrt(b / 2)
            and poly.cut(a, b, self.tol)
        ):
            self._enqueue(c)

    def _polytope(self, i: int) -> _Polytope:
        """Chart ``i``'s polytope, built from its recorded planes on first use."""
        poly = self.polys[i]
        if poly is None:
            poly = _Polytope.from_planes(self.k, self.r, self.planes[i], self.offsets[i])
            self.polys[i] = poly
            self.planes[i], self.offsets[i] = [], []
        return poly

    def _enqueue(self, c: int) -> None:
        if not self.queued[c]:
            poly = self.polys[c]
            if poly is None or poly.expandable(self.r**2) >= 0:
                self.queued[c] = True
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
                self.queued[i] = False
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
                    if _crossing_sign(self.PHI[i], point.phi, point.sign) != self.signs[i]:
                        self._locate_crossing(i, direction, alpha)
                    self.add_chart(point, i)
                    return True
            alpha *= _SHRINK  # Algorithm 1, line 11
        poly.blocked[v] = True
        self.boundary[i] = True
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
        self.boundary[i] = True
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

    def _accept(self, i: int, x_j: FloatArray) -> _Point | None:
        """``x_j`` as a new centre, or None when ``J`` drops rank there or Eq. (18) fails."""
        point = _regular_point(self.J, x_j, self.k, self.scale)
        if point is None:
            self._add_singular(x_j)
            self.counters.rejections += 1
            return None
        if _min_cosine(self.PHI[i], point.phi) < 1.0 - self.settings.epsilon:  # Eq. (18)
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
            point = _regular_point(self.J, x, self.k, self.scale)
            if point is None:
                break
            if _crossing_sign(phi_i, point.phi, point.sign) == self.signs[i]:
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
        sizes = [len(nb) for nb in self.nbrs]
        edges = np.stack((np.concatenate(self.nbrs), np.repeat(np.arange(N), sizes)), axis=1)
        return Atlas(
            centres=self.X[:N].copy(),
            tangents=self.PHI[:N].copy(),
            radius=self.r,
            epsilon=self.settings.epsilon,
            edges=edges.astype(np.int64),
            parents=np.array(self.parents, dtype=np.int64),
            boundary=np.array(self.boundary, dtype=bool),
            open=np.array(self.queued, dtype=bool),
            singular_points=np.array(self.singular).reshape(-1, n),
            newton_failures=self.counters.newton_failures,
            rejections=self.counters.rejections,
            bound_rejections=self.counters.bound_rejections,
            build_seconds=seconds,
            stop_reason="max_charts" if any(self.queued) else "complete",
        )


# --------------------------------------------------------------------------------------------
# Input checks and the public entry point.
# --------------------------------------------------------------------------------------------


def _bounds(value: ArrayLike | None, n: int, fill: float, what: str) -> FloatArray:
    if value is None:
        return np.full(n, fill)
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape != (n,) or np.isnan(arr).any():
        raise AtlasError(f"{what} must be {n} numbers (use +-inf for no bound), got {arr!r}")
    return arr


def _start(F: Function, J: Function, x0: ArrayLike, k: int, settings: AtlasSettings) -> _Point:
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
    point = _regular_point(J, x, k)
    if point is None:
        raise AtlasError(
            f"J(x0) has rank {np.linalg.matrix_rank(jac)} < n - k = {n - k}: x0 is a singular "
            f"point, or the solution set has a dimension larger than k = {k}; pass a regular start "
            "point and k = n - rank(J)"
        )
    projected = project(F, J, x, point.phi, settings.newton_tol, settings.newton_max_iter)
    point = None if projected is None else _regular_point(J, projected, k)
    if point is None:
        raise AtlasError("the Newton projection of x0 onto F = 0 failed or met a singular point")
    return point


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
    point = _start(F, J, x0, k, settings)
    lo = _bounds(lower, point.x.size, -np.inf, "lower")
    hi = _bounds(upper, point.x.size, np.inf, "upper")
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
