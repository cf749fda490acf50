"""The continuation (Algorithm 1): expand charts from the start until the component is covered."""

from __future__ import annotations

import contextlib
import gc
import operator
import time
from collections import deque
from collections.abc import Callable, Iterator
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas import checkpoint as _checkpoint
from sahgrasp.atlas.checkpoint import AtlasCheckpoint
from sahgrasp.atlas.checks import check_bounds, start_point
from sahgrasp.atlas.model import Atlas, AtlasSettings, FloatArray, Function, IndexArray
from sahgrasp.atlas.neighbours import NeighbourIndex
from sahgrasp.atlas.polytope import CUT_TOL, Polytope, compatible
from sahgrasp.atlas.projection import (
    Point,
    crossing_sign,
    crossing_signs,
    min_cosine,
    min_cosines,
    project,
    project_many,
    regular_point,
    tangent_many,
)
from sahgrasp.core.errors import AtlasError
from sahgrasp.core.progress import ProgressCallback, StderrProgress

__all__ = ["build_atlas"]

_SHRINK = 0.9  # Algorithm 1, line 11: alpha <- 0.9 alpha
_BISECTIONS = 40  # steps to locate a branch crossing along a chart's parameter ray
_PROGRESS_STAGE = "atlas charts"


def _shaping(settings: AtlasSettings) -> dict[str, Any]:
    """The settings that shape the atlas (a checkpoint resumes only under the same ones)."""
    shaping = asdict(settings)
    for name in ("max_charts", "progress"):  # how far and how loudly, not which atlas
        del shaping[name]
    return {name: float(v).hex() if isinstance(v, float) else v for name, v in shaping.items()}


class _Rowwise:
    """``F`` and ``J`` of one point applied to each row of a stack of points.

    ``J`` is evaluated right after ``F`` at every point and kept until asked for: a user's
    ``F`` and ``J`` often share the work of the last point they saw (the SAH's kinematics and
    surface jets), which row-by-row ``F`` then row-by-row ``J`` would lose. Nearly every point
    needs ``J`` after ``F`` (a Newton step or, once converged, its tangent space).
    """

    __slots__ = ("_F", "_J", "_jacobians")

    def __init__(self, F: Function, J: Function) -> None:
        self._F, self._J = F, J
        self._jacobians: dict[bytes, FloatArray] = {}

    def F(self, X: FloatArray) -> FloatArray:
        """``F`` at each row of ``X`` (B, n), keeping ``J`` there."""
        rows = []
        for x in X:
            rows.append(self._F(x))
            self._jacobians[x.tobytes()] = self._J(x)
        return np.array(rows)

    def J(self, X: FloatArray) -> FloatArray:
        """``J`` at each row of ``X`` (B, n): the kept one where :meth:`F` saw the row."""
        kept = [self._jacobians.get(x.tobytes()) for x in X]
        return np.array([self._J(x) if j is None else j for x, j in zip(X, kept, strict=True)])

    def clear(self) -> None:
        """Forget the kept Jacobians (after a wave's first tries)."""
        self._jacobians.clear()


@dataclass(frozen=True)
class _Wave:
    """The first try (step ``alpha = r``) of every chart of a wave, computed in stacked calls.

    Attributes:
        picks: ``(chart, vertex index)`` pairs, oldest chart first.
        polys: The picked charts' polytopes.
        vertices: The picked vertices (a later cut may renumber them).
        verts: The same as an array, shape (B, k).
        parent_x: The picked charts' centres, shape (B, n).
        parent_phi: Their tangent bases, shape (B, n, k).
        directions: Unit vectors towards the vertices, shape (B, k).
        x: Projected candidates, shape (B, n).
        outcome: Per pick one of the ``_OK``, ``_NEWTON``, ... codes below.
        phi: Tangent bases at the candidates (rows of accepted ones only), shape (B, n, k).
        sign: ``sign(det([J; phi^T]))`` there, shape (B,).
        crossed: The sign changed from the parent's (a branch crossing), shape (B,).
    """

    picks: list[tuple[int, int]]
    polys: list[Polytope]
    vertices: list[tuple[float, ...]]
    verts: FloatArray
    parent_x: FloatArray
    parent_phi: FloatArray
    directions: FloatArray
    x: FloatArray
    outcome: IndexArray
    phi: FloatArray
    sign: FloatArray
    crossed: NDArray[np.bool_]


# Outcomes of a wave's first try; a deferred pick was not tried (see _Builder._first_try).
_OK, _NEWTON, _FAR, _OUTSIDE, _SINGULAR, _TURNED, _DEFERRED = range(7)


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
        stacked: bool = False,
    ) -> None:
        self.F, self.J, self.k, self.settings = F, J, k, settings
        self.rowwise = None if stacked else _Rowwise(F, J)
        self.F_many = F if self.rowwise is None else self.rowwise.F
        self.J_many = J if self.rowwise is None else self.rowwise.J
        self.lower, self.upper = bounds
        self.scale = scale  # size of J at the start, for the rank test of single equations
        self.bounded = bool((np.isfinite(self.lower) | np.isfinite(self.upper)).any())
        self.r = settings.radius
        self.tol = CUT_TOL * self.r
        # cos(2 theta)^2 of the branch test (see _similar), theta = acos(1 - epsilon) of Eq. (18)
        self.alike_threshold = max(2.0 * (1.0 - settings.epsilon) ** 2 - 1.0, 0.0) ** 2
        n = self.lower.size
        self.X = np.empty((1024, n))
        self.PHI = np.empty((1024, n, k))
        self.closed = np.zeros(1024, dtype=bool)  # left the queue and not boundary: takes no cuts
        self.charts: list[_Chart] = []  # chart i: centre X[i], basis PHI[i], the rest here
        self.new_charts: Callable[[FloatArray], None] | None = None
        self.singular: list[FloatArray] = []
        self.count = 0
        self.index = NeighbourIndex()
        self.queue: deque[int] = deque()
        self.counters = _Counters()
        self.blocked = 0  # vertices blocked (every step failed), for the "stalled" verdict

    # -- adding a chart ------------------------------------------------------------------------

    def _grow(self) -> None:
        for name in ("X", "PHI", "closed"):
            old = getattr(self, name)
            new = np.zeros((2 * old.shape[0], *old.shape[1:]), dtype=old.dtype)
            new[: self.count] = old[: self.count]
            setattr(self, name, new)

    def add_chart(self, point: Point, parent: int) -> None:
        """Add one chart (see :meth:`add_charts`)."""
        # Contiguous copies: matmul may round a strided basis (a view of Q) differently.
        self.add_charts(np.array([point.x]), np.array([point.phi]), [point.sign], [parent])

    def add_charts(
        self, new: FloatArray, phis: FloatArray, signs: list[float], parents: list[int]
    ) -> None:
        """Add charts in order; give each and each neighbour the other's plane.

        The charts have centres ``new`` (B, n), bases ``phis`` (B, n, k), the signs of
        ``det([J; phi^T])`` and the parents given. Neighbour search, the branch test and the
        planes (Fig. 6b) are computed for all new charts at once; the planes then cut the
        neighbours' polytopes one by one, chart after chart.
        """
        count = len(new)
        while self.count + count > self.X.shape[0]:
            self._grow()
        j0 = self.count
        rows, cols = self.index.query(self.X, j0, new, 2 * self.r)
        gap = new[:, None] - new[None]  # charts of the same wave neighbour the later one
        later, earlier = np.nonzero((gap * gap).sum(axis=2) < 4 * self.r**2)
        below = earlier < later  # the lower triangle, without np.tril's mask building
        later, earlier = later[below], earlier[below]
        # Grouped by new chart: earlier charts (index tree, then its tail), then the same wave.
        owners = np.concatenate((rows, later))
        order = np.argsort(owners, kind="stable")
        owner = owners[order]
        nbrs = np.concatenate((cols, j0 + earlier)).astype(np.int64)[order]
        self.X[j0 : j0 + count], self.PHI[j0 : j0 + count] = new, phis
        if self.new_charts is not None:
            self.new_charts(new)
        bases, own = self.PHI[nbrs], phis[owner]
        similar = self._similar(bases, own)
        diff = new[owner] - self.X[nbrs]
        # Neighbour centres in each chart's parameters; the sphere |w| = r and the sphere of
        # radius r around u meet on the plane u . w = |u|^2 / 2. (matmul: einsum costs twice as
        # much per call on these small stacks.)
        U = -np.matmul(diff[:, None, :], own)[:, 0]
        Uc = np.matmul(diff[:, None, :], bases)[:, 0]
        B = 0.5 * (U * U).sum(axis=1)
        Bc = 0.5 * (Uc * Uc).sum(axis=1)
        small = self.tol * self.r  # a neighbour straight along the normal gives no plane
        mine = similar & (small < B)
        # A closed chart ignores new planes for good: select only the rest (see _give_plane).
        theirs = similar & (small < Bc) & ~self.closed[nbrs]
        # Everything the per-chart loop needs as plain lists: one conversion per wave.
        kept, own, give = (np.cumsum(np.bincount(owner[m], minlength=count)).tolist()
                           for m in (similar, mine, theirs))  # fmt: skip
        kept_nbrs = nbrs[similar]
        planes, offsets = U[mine].tolist(), B[mine].tolist()
        targets, normals, given = nbrs[theirs].tolist(), Uc[theirs].tolist(), Bc[theirs].tolist()
        start = [0, 0, 0]
        for q, (sign, parent) in enumerate(zip(signs, parents, strict=True)):
            (k0, o0, g0), k1, o1, g1 = start, kept[q], own[q], give[q]
            self.charts.append(
                _Chart(sign, parent, kept_nbrs[k0:k1], planes[o0:o1], offsets[o0:o1])
            )
            self.count = j0 + q + 1
            for c, a, b in zip(targets[g0:g1], normals[g0:g1], given[g0:g1], strict=True):
                self._give_plane(c, a, b)
            self._enqueue(self.count - 1)
            start = [k1, o1, g1]
        self.index.added(self.X, self.count)

    def _similar(self, bases: FloatArray, phis: FloatArray) -> NDArray[np.bool_]:
        """Which of the tangent bases ``bases`` (q, n, k) are close enough to ``phis`` (q, n, k).

        Eq. (18) lets a chart turn by ``theta = acos(1 - epsilon)`` from its parent at distance
        ``r``; neighbours (distance < 2r) turned by more than ``2 theta`` lie on another branch (a
        crossing, a cone's apex) and must not bound each other, so that the continuation passes
        through. ``|M|_F^2 - (k - 1)`` bounds the squared smallest singular value of M from below.
        """
        M = np.matmul(phis.transpose(0, 2, 1), bases)  # (q, k, k): phi^T Phi_c
        threshold = self.alike_threshold
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
            poly = Polytope.from_planes(self.k, self.r, chart.planes, chart.offsets, self.tol)
            chart.poly, chart.planes, chart.offsets = poly, [], []
        return poly

    def _enqueue(self, c: int) -> None:
        chart = self.charts[c]
        if not chart.queued:
            poly = chart.poly
            if poly is None or poly.expandable(self.r**2) >= 0:
                chart.queued = True
                self.queue.append(c)

    def _dequeue(self, i: int) -> None:
        """Chart ``i`` left the queue with no expandable vertex.

        Unless it is a boundary chart (a later cut may uncover a blocked vertex), no plane can
        make it expandable again: it is closed and :meth:`add_charts` gives it no more planes.
        """
        chart = self.charts[i]
        chart.queued = False
        self.closed[i] = not chart.boundary

    # -- expanding -----------------------------------------------------------------------------

    def run(
        self, progress: ProgressCallback | None, between: Callable[[], None] | None = None
    ) -> None:
        """Expand charts until every one is bounded or ``max_charts`` is reached.

        ``between`` is called after every wave (or every chart expansion, batch 1): a state the
        build passes through, which a checkpoint can save.

        ``progress`` hears of every new chart: ``done`` charts of ``total``, the charts built
        plus those still open (queued), at most ``max_charts``. The total grows while the
        frontier does and meets ``done`` when the atlas is complete.
        """
        r2, cap = self.r**2, self.settings.max_charts
        if progress is not None:
            progress(_PROGRESS_STAGE, self.count, self._progress_total())
        while self.queue and self.count < cap:
            if self.settings.batch > 1:
                before = self.count
                self._run_wave()
                if progress is not None:  # every new chart, as one-chart expansion reports
                    total = self._progress_total()
                    for done in range(before + 1, self.count + 1):
                        progress(_PROGRESS_STAGE, done, total)
            else:
                i = self.queue[0]
                v = self._polytope(i).expandable(r2)
                if v < 0:
                    self.queue.popleft()
                    self._dequeue(i)
                elif self.expand(i, v) and progress is not None:
                    progress(_PROGRESS_STAGE, self.count, self._progress_total())
            if between is not None:
                between()
        if progress is not None:  # the last total: the charts built
            progress(_PROGRESS_STAGE, self.count, self.count)

    def _progress_total(self) -> int:
        """The charts built plus the open frontier (queued charts), capped at ``max_charts``."""
        return min(self.count + len(self.queue), self.settings.max_charts)

    def expand(self, i: int, v: int, alpha: float | None = None) -> bool:
        """Try to create a chart from vertex ``v`` of chart ``i`` (Algorithm 1, lines 7-13).

        ``alpha`` is the first step (``r`` when None; a wave passes ``0.9 r`` after its own
        try at ``r`` failed). Returns True when a chart was added. Otherwise either a box bound
        the candidates crossed cut ``v`` off, or ``v`` is blocked after every step down to
        ``min_step * r`` failed.
        """
        poly = self._polytope(i)
        vertex = poly.vertex(v)
        direction = np.array(vertex) / np.sqrt(poly.vertex_norm2(v))
        alpha = self.r if alpha is None else alpha
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
        poly.block(v)
        self.blocked += 1
        self.charts[i].boundary = True
        return False

    # -- expanding a wave of charts ------------------------------------------------------------

    def _pick(self) -> list[tuple[int, int]]:
        """Up to ``batch`` queued charts with an expandable vertex, oldest first, and the vertex.

        Charts without one leave the queue, as they do at its head in one-chart expansion.
        """
        r2, queue = self.r**2, self.queue
        room = min(self.settings.batch, self.settings.max_charts - self.count)
        picks: list[tuple[int, int]] = []
        while queue and len(picks) < room:
            i = queue.popleft()
            v = self._polytope(i).expandable(r2)
            if v < 0:
                self._dequeue(i)
            else:
                picks.append((i, v))
        queue.extendleft(reversed([i for i, _ in picks]))
        return picks

    def _first_try(self, picks: list[tuple[int, int]]) -> _Wave:
        """Eqs. (14)-(18) at step ``r`` for the picks at once: stacked Newton, QR and SVD.

        A pick whose try is bound to be left out by :meth:`_compatible` is deferred without a
        projection (it stays queued): the test runs first on the unprojected candidates
        ``x_tilde``, with the parents' tangent spaces. Where ``F`` and ``J`` are costly (the SAH,
        whose wave front is narrow) this saves most of the projections that would be discarded.
        """
        s = self.settings
        charts = [i for i, _ in picks]
        rows = np.array(charts)
        polys = [self._polytope(i) for i in charts]
        vertices = [p.vertex(v) for p, (_, v) in zip(polys, picks, strict=True)]
        verts = np.array(vertices)
        norms = np.sqrt([p.vertex_norm2(v) for p, (_, v) in zip(polys, picks, strict=True)])
        directions = verts / norms[:, None]
        parent_x, phi_all = self.X[rows], self.PHI[rows]
        x = parent_x + np.matmul(phi_all, self.r * directions[:, :, None])[:, :, 0]
        outcome = np.full(len(picks), _DEFERRED)
        tried = np.array(self._compatible(polys, parent_x, phi_all, verts, x, phi_all), np.int64)
        phi_i, x_tilde = phi_all[tried], x[tried]
        x_t, converged = project_many(
            self.F_many, self.J_many, x_tilde, phi_i, s.newton_tol, s.newton_max_iter
        )
        result = np.where(converged, _OK, _NEWTON)
        dx = np.where(converged[:, None], x_t - x_tilde, 0.0)  # diverged ones: no overflow
        result[(result == _OK) & ((dx * dx).sum(axis=1) > s.epsilon**2)] = _FAR  # Eq. (17)
        if self.bounded:
            outside = ((x_t < self.lower) | (x_t > self.upper)).any(axis=1)
            result[(result == _OK) & outside] = _OUTSIDE
        phi = np.zeros_like(phi_all)
        sign = np.ones(len(picks))
        crossed = np.zeros(len(picks), dtype=bool)
        good = np.flatnonzero(result == _OK)
        if good.size:
            phi_g, sign_g, regular = tangent_many(self.J_many(x_t[good]), self.k, self.scale)
            turned = min_cosines(phi_i[good], phi_g) < 1.0 - s.epsilon  # Eq. (18)
            result[good[turned]] = _TURNED
            result[good[~regular]] = _SINGULAR
            at = tried[good]
            phi[at], sign[at] = phi_g, sign_g
            parent_sign = np.array([self.charts[i].sign for i in rows[at].tolist()])
            crossed[at] = crossing_signs(phi_i[good], phi_g, sign_g) != parent_sign
        x[tried], outcome[tried] = x_t, result
        if self.rowwise is not None:
            self.rowwise.clear()
        return _Wave(
            picks, polys, vertices, verts, parent_x, phi_all, directions, x, outcome, phi, sign,
            crossed,
        )  # fmt: skip

    def _compatible(
        self,
        polys: list[Polytope],
        parent_x: FloatArray,
        parent_phi: FloatArray,
        verts: FloatArray,
        x: FloatArray,
        phi: FloatArray,
    ) -> list[int]:
        """Which of the new centres ``x`` (tangent bases ``phi``) can all be added, in order.

        Centre q comes from the picked vertex ``verts[q]`` of the chart with polytope
        ``polys[q]``, centre ``parent_x[q]`` and basis ``parent_phi[q]``. Each must be the try
        one-chart expansion would make after the earlier accepted ones: their planes (as
        :meth:`add_charts` would cut its chart's polytope, alike charts only) must neither cut
        off its picked vertex nor create a nearer exterior vertex. One that fails is left out;
        its chart stays queued. Compiled (``_polytope.compatible``): called twice a wave, its
        pairs and sequential loop cost about 100 us a call in numpy and Python.
        """
        if not polys:
            return []
        return compatible(
            polys, x, parent_x, phi, parent_phi, verts, self.r, self.r**2, self.tol,
            self.alike_threshold,
        )  # fmt: skip

    def _still_picked(self, i: int, vertex: tuple[float, ...]) -> int:
        """Index of ``vertex`` if chart ``i`` would still expand it (-1 if not).

        A new chart's plane may have cut it off or created a nearer exterior vertex.
        """
        poly = self._polytope(i)
        v = poly.expandable(self.r**2)
        return v if v >= 0 and poly.vertex(v) == vertex else -1

    def _run_wave(self) -> None:
        """Expand a wave of up to ``batch`` charts: first tries and new charts stacked.

        The successful first tries that do not cut off each other's vertex are added at once,
        so the atlas is the one-chart atlas of another expansion order: covering and
        deterministic. Then each chart whose first try failed goes on with smaller steps, one at
        a time, unless a new chart cut off (or renumbered into a different nearest vertex) its
        picked vertex; then, as a chart whose try was left out or deferred, it stays queued.
        """
        picks = self._pick()
        if not picks:
            return
        wave = self._first_try(picks)
        ok = np.flatnonzero(wave.outcome == _OK)
        polys = [wave.polys[p] for p in ok.tolist()]
        parent_x, parent_phi, verts = wave.parent_x[ok], wave.parent_phi[ok], wave.verts[ok]
        tries = self._compatible(polys, parent_x, parent_phi, verts, wave.x[ok], wave.phi[ok])
        added = ok[tries].tolist()
        for p in added:
            if wave.crossed[p]:
                self._locate_crossing(picks[p][0], wave.directions[p], self.r)
        if added:
            parents = [picks[p][0] for p in added]
            self.add_charts(wave.x[added], wave.phi[added], wave.sign[added].tolist(), parents)
        c = self.counters
        for p in np.flatnonzero((wave.outcome != _OK) & (wave.outcome != _DEFERRED)).tolist():
            i = picks[p][0]
            v = self._still_picked(i, wave.vertices[p])
            if v < 0:
                continue
            poly = self._polytope(i)
            vertex = poly.vertex(v)
            outcome = int(wave.outcome[p])
            if outcome == _NEWTON:
                c.newton_failures += 1
            elif outcome == _OUTSIDE:
                if self._cut_by_bounds(i, wave.x[p], vertex):
                    continue
                v = poly.index(vertex)  # the cut may have renumbered the vertices
            else:
                if outcome == _SINGULAR:
                    self._add_singular(wave.x[p])
                c.rejections += 1
            self.expand(i, v, self.r * _SHRINK)

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

    # -- checkpoints ---------------------------------------------------------------------------

    def state(self, seconds: float) -> tuple[dict[str, Any], dict[str, NDArray[Any]]]:
        """The whole state as JSON-able meta data and flat arrays (see ``atlas.checkpoint``).

        A closed chart's polytope is left out: nothing reads it again (no plane is given to it,
        it never re-enters the queue).
        """
        N, k, charts = self.count, self.k, self.charts
        pending = [len(c.offsets) for c in charts]
        planes = [p for c in charts for p in c.planes]
        closed = self.closed[:N]
        polys = [b"" if c.poly is None or closed[i] else c.poly.to_bytes()
                 for i, c in enumerate(charts)]  # fmt: skip
        s, c = self.settings, self.counters
        meta = {
            "k": k,
            "n": int(self.X.shape[1]),
            "charts": N,
            "seconds": seconds,
            "settings": _shaping(s),
            "scale": float(self.scale).hex(),
            "n_tree": self.index.indexed,
            "counters": [c.newton_failures, c.rejections, c.bound_rejections, self.blocked],
        }
        arrays = {
            "centres": self.X[:N],
            "tangents": self.PHI[:N],
            "closed": closed,
            "lower": self.lower,
            "upper": self.upper,
            "sign": np.array([c.sign for c in charts]),
            "parent": np.array([c.parent for c in charts], dtype=np.int64),
            "boundary": np.array([c.boundary for c in charts], dtype=bool),
            "queued": np.array([c.queued for c in charts], dtype=bool),
            "nbr_sizes": np.array([len(c.nbrs) for c in charts], dtype=np.int64),
            "nbrs": np.concatenate([c.nbrs for c in charts]).astype(np.int64),
            "plane_sizes": np.array(pending, dtype=np.int64),
            "planes": np.array(planes, dtype=np.float64).reshape(-1, k),
            "offsets": np.array([b for c in charts for b in c.offsets], dtype=np.float64),
            "poly_sizes": np.array([len(b) for b in polys], dtype=np.int64),
            "polys": np.frombuffer(b"".join(polys), dtype=np.uint8),
            "queue": np.array(list(self.queue), dtype=np.int64),
            "singular": np.array(self.singular).reshape(-1, self.X.shape[1]),
        }
        return meta, arrays

    def restore(self, meta: dict[str, Any], arrays: dict[str, NDArray[Any]]) -> None:
        """Take the state :meth:`state` gave (checked against this build by the caller)."""
        N = int(meta["charts"])
        while self.X.shape[0] < N:
            self._grow()
        self.X[:N], self.PHI[:N], self.closed[:N] = (
            arrays["centres"],
            arrays["tangents"],
            arrays["closed"],
        )
        cuts = [np.cumsum(np.concatenate(([0], arrays[name]))).tolist()
                for name in ("nbr_sizes", "plane_sizes", "poly_sizes")]  # fmt: skip
        nbrs, planes, offsets = arrays["nbrs"], arrays["planes"].tolist(), arrays["offsets"]
        polys = arrays["polys"].tobytes()
        self.charts = []
        for i, (sign, parent, boundary, queued) in enumerate(zip(
            arrays["sign"].tolist(), arrays["parent"].tolist(), arrays["boundary"].tolist(),
            arrays["queued"].tolist(), strict=True,
        )):  # fmt: skip
            p0, p1 = cuts[2][i], cuts[2][i + 1]
            self.charts.append(_Chart(
                sign, parent, nbrs[cuts[0][i] : cuts[0][i + 1]].copy(),
                planes[cuts[1][i] : cuts[1][i + 1]], offsets[cuts[1][i] : cuts[1][i + 1]].tolist(),
                Polytope.from_bytes(polys[p0:p1]) if p1 > p0 else None, boundary, queued,
            ))  # fmt: skip
        self.count = N
        self.queue = deque(arrays["queue"].tolist())
        self.singular = [row.copy() for row in arrays["singular"]]
        c = self.counters
        c.newton_failures, c.rejections, c.bound_rejections, self.blocked = meta["counters"]
        self.index.restore(self.X, int(meta["n_tree"]))
        if self.new_charts is not None:
            self.new_charts(self.X[:N].copy())

    def _stop_reason(self, still_open: NDArray[np.bool_]) -> str:
        """Why the build ended (one of ``STOP_REASONS``).

        ``"max_charts"`` with charts still open; ``"stalled"`` when the start chart alone remains
        with blocked vertices (no step of any size was accepted); else ``"complete"``.
        """
        if still_open.any():
            return "max_charts"
        return "stalled" if self.count == 1 and self.blocked else "complete"

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
            stop_reason=self._stop_reason(still_open),
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
    stacked: bool = False,
    new_charts: Callable[[FloatArray], None] | None = None,
    checkpoint: AtlasCheckpoint | None = None,
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
        progress: Called after every new chart as ``progress("atlas charts", charts, total)``,
            ``total`` the charts built plus the open frontier (at most ``max_charts``), and once
            more at the end with ``total = charts``; with None, ``settings.progress`` draws a
            bar on stderr.
        stacked: ``F`` and ``J`` also take a stack of points, ``(B, n) -> (B, n - k)`` and
            ``(B, n - k, n)``; a wave (``settings.batch > 1``) then evaluates them once per
            Newton iteration for all its charts instead of point by point.
        new_charts: Called with the centres of every chart added, (B, n) at a time, in the
            order of ``atlas.centres`` (a chart's centre never changes once added); on a resumed
            build, first with every centre of the checkpoint.
        checkpoint: Save the build's state to ``checkpoint.path`` every
            ``checkpoint.every_seconds``, on Ctrl-C, SIGTERM or SIGHUP (then KeyboardInterrupt
            is raised) and at the end; with ``checkpoint.resume``, start from the state saved
            there. The resumed atlas equals an uninterrupted one, array for array
            (``build_seconds`` adds up the runs).

    Returns:
        The atlas; when ``max_charts`` stopped the build, ``atlas.stop_reason`` is
        ``"max_charts"`` and ``atlas.complete`` is False; when not a single chart could be
        added to the start (the radius is far too large or small for the manifold), it is
        ``"stalled"``.

    Raises:
        AtlasError: Shapes of ``F``/``J`` disagree with ``n`` and ``k``, ``x0`` is off the manifold,
            singular or outside the bounds, or the settings are invalid; the checkpoint is
            another problem's, damaged, or written by another build at the same time.
        KeyboardInterrupt: Interrupted while saving checkpoints (the state is saved first).
    """
    with _collections_of_new_objects():
        return _build(F, J, x0, k, settings, lower, upper, progress, stacked, new_charts,
                      checkpoint)  # fmt: skip


def _build(
    F: Function,
    J: Function,
    x0: ArrayLike,
    k: int,
    settings: AtlasSettings | None,
    lower: ArrayLike | None,
    upper: ArrayLike | None,
    progress: ProgressCallback | None,
    stacked: bool,
    new_charts: Callable[[FloatArray], None] | None,
    checkpoint: AtlasCheckpoint | None,
) -> Atlas:
    """:func:`build_atlas`'s work (its arguments)."""
    start_time = time.perf_counter()
    settings = settings or AtlasSettings()
    point = start_point(F, J, x0, k, settings)
    lo = check_bounds(lower, point.x.size, -np.inf, "lower")
    hi = check_bounds(upper, point.x.size, np.inf, "upper")
    if (point.x < lo).any() or (point.x > hi).any():
        raise AtlasError("x0 lies outside the box [lower, upper]; the start must lie within it")
    scale = float(np.sqrt(np.einsum("ij,ij->i", J(point.x), J(point.x))).max())
    builder = _Builder(F, J, k, (lo, hi), scale, settings, stacked)
    builder.new_charts = new_charts
    if checkpoint is None:
        builder.add_chart(point, -1)
        _run(builder, settings, progress, None)
        return builder.result(time.perf_counter() - start_time)
    with _checkpoint.checkpoint_lock(checkpoint.path):
        earlier = _resumed(builder, checkpoint, point) if checkpoint.resume else None
        if earlier is None:
            earlier = 0.0
            builder.add_chart(point, -1)
        saver = _Saver(builder, checkpoint, start_time - earlier)
        with _checkpoint.deferred_interrupts() as flag:
            saver.flag = flag
            _run(builder, settings, progress, saver)
        saver.save()
    return builder.result(time.perf_counter() - start_time + earlier)


@contextlib.contextmanager
def _collections_of_new_objects() -> Iterator[None]:
    """While the build runs, the garbage collector scans only the objects created meanwhile.

    A build allocates hundreds of thousands of small containers (plane lists, chart records);
    the first build in a process otherwise triggers full collections that traverse every object
    the process holds (numpy's, scipy's, Pinocchio's: some 10^5), which made the first build of
    S^2 about twice as long as the next ones. ``gc.freeze`` sets the existing objects aside and
    ``gc.unfreeze`` puts them back afterwards; a caller who froze objects keeps them frozen (then
    nothing is done here).
    """
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def _run(
    builder: _Builder,
    settings: AtlasSettings,
    progress: ProgressCallback | None,
    between: Callable[[], None] | None,
) -> None:
    if progress is None and settings.progress:
        with StderrProgress() as bar:
            builder.run(bar, between)
    else:
        builder.run(progress, between)


class _Saver:
    """Writes the builder's state when due, and on an interrupt before raising it."""

    def __init__(self, builder: _Builder, checkpoint: AtlasCheckpoint, origin: float) -> None:
        self.builder, self.checkpoint, self.origin = builder, checkpoint, origin
        self.last = time.perf_counter()
        self.flag: Any = None

    def save(self) -> None:
        now = time.perf_counter()
        meta, arrays = self.builder.state(now - self.origin)
        meta["key"] = self.checkpoint.key
        _checkpoint.write(self.checkpoint.path, meta, arrays)
        self.last = time.perf_counter()

    def __call__(self) -> None:
        if self.flag is not None and self.flag.raised:
            self.save()
            raise KeyboardInterrupt
        if time.perf_counter() - self.last >= self.checkpoint.every_seconds:
            self.save()


def _resumed(builder: _Builder, checkpoint: AtlasCheckpoint, point: Point) -> float | None:
    """Restore the checkpoint's state into ``builder``; its build seconds (None: no file).

    Raises:
        AtlasError: The file belongs to another problem or other settings.
    """
    try:
        meta, arrays = _checkpoint.read(checkpoint.path)
    except FileNotFoundError:
        return None
    path = checkpoint.path
    mismatch = [
        what
        for what, ours, theirs in (
            ("key", checkpoint.key, meta.get("key")),
            ("k", builder.k, meta.get("k")),
            ("n", builder.X.shape[1], meta.get("n")),
            ("settings", _shaping(builder.settings), meta.get("settings")),
            ("scale", float(builder.scale).hex(), meta.get("scale")),
        )
        if ours != theirs
    ]
    centres = arrays.get("centres")
    if (
        centres is None
        or centres.ndim != 2
        or not len(centres)
        or (centres[0].tobytes() != point.x.tobytes())
    ):
        mismatch.append("start point")
    for name, ours in (("lower", builder.lower), ("upper", builder.upper)):
        if arrays.get(name) is None or arrays[name].tobytes() != ours.tobytes():
            mismatch.append(f"{name} bounds")
    if mismatch:
        raise AtlasError(
            f"the checkpoint {path} was written for another problem (its {', '.join(mismatch)} "
            "differ); resume with the same problem and settings, or start afresh without resume"
        )
    try:
        builder.restore(meta, arrays)
    except (KeyError, ValueError, TypeError, IndexError) as exc:
        raise AtlasError(f"the checkpoint {path} is damaged ({exc}); start afresh") from None
    return float(meta["seconds"])
