"""Chart domains: convex polytopes in a chart's parameter space, cut by neighbours' half-spaces."""

from __future__ import annotations

import functools
import itertools
import operator

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from sahgrasp.atlas.model import FloatArray

__all__ = ["CUT_TOL", "Polytope"]

_MASK_BITS = 62  # facets a Qhull-built polytope may have (one bit each of an int64 mask)
CUT_TOL = 1e-9  # a vertex closer than this (times r) to a plane lies on it
_BITS = np.left_shift(1, np.arange(_MASK_BITS, dtype=np.int64))  # face h's bit in a mask


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


class Polytope:
    """Convex polytope in a chart's parameter space, vertex/face incidence as integer bit masks.

    Plain Python lists: a polytope has a handful of vertices (k <= 3), where per-call numpy overhead
    would dominate the incremental cuts. For k = 2 the vertices go round the polygon counter-
    clockwise, so that a cut is a clip of consecutive vertices (:meth:`_clip`).
    """

    __slots__ = ("blocked", "masks", "norm2", "reach2", "verts")

    def __init__(
        self, verts: list[tuple[float, ...]], masks: list[int], norm2: list[float] | None = None
    ) -> None:
        """Vertices, their face masks and (when known) their squared norms."""
        self.verts = verts
        self.masks = masks
        self.blocked = [False] * len(verts)
        self.norm2 = [sum(map(operator.mul, v, v)) for v in verts] if norm2 is None else norm2
        self.reach2 = max(self.norm2)  # squared distance of the farthest vertex

    @classmethod
    def cube(cls, k: int, r: float) -> Polytope:
        """The k-cube ``[-r, r]^k`` enclosing the ball ``B_i`` (Fig. 6a); face 2d+s is x_d = -+r."""
        verts = list(itertools.product((-r, r), repeat=k))
        if k == 2:  # counter-clockwise, as the polygon cut expects
            verts = [verts[0], verts[2], verts[3], verts[1]]
        masks = [sum(1 << (2 * d + (c < 0)) for d, c in enumerate(v)) for v in verts]
        return cls(verts, masks)

    @classmethod
    def from_planes(
        cls, k: int, r: float, planes: list[list[float]], offsets: list[float]
    ) -> Polytope:
        """The cube ``[-r, r]^k`` cut by every half-space ``planes[h] . w <= offsets[h] (> 0)``.

        For k >= 2 all cuts are made at once through polar duality: the polytope
        ``{w : p_h . w <= 1}``, ``p_h = planes[h] / offsets[h]``, has one vertex per facet of the
        convex hull of the ``p_h``. k = 1, or a degenerate hull, falls back to one cut per plane.
        """
        tol = CUT_TOL * r
        if k == 2:
            inv = 1.0 / r
            cube = [[inv, 0.0], [-inv, 0.0], [0.0, inv], [0.0, -inv]]
            return cls._from_dual_polygon(
                cube + [[a / b, c / b] for (a, c), b in zip(planes, offsets, strict=True)]
            )
        if k >= 3:
            dual = np.array(planes).reshape(-1, k) / np.array(offsets)[:, None]
            poly = cls._from_qhull(np.concatenate((_cube_normals(k) / r, dual)), tol)
            if poly is not None:
                return poly
        poly = cls.cube(k, r)
        for a, off in zip(planes, offsets, strict=True):
            poly.cut(list(a), off, tol)
        return poly

    @classmethod
    def _from_qhull(cls, dual: FloatArray, tol: float) -> Polytope | None:
        """Polytope ``{w : dual @ w <= 1}`` from Qhull's hull of ``dual``; None if degenerate."""
        try:
            hull = ConvexHull(dual)
        except QhullError:
            return None
        # The planes that are facets of the polytope: the dual points on the hull (marked rather
        # than hull.vertices, which sorts them with np.unique at several times the cost).
        on_hull = np.zeros(len(dual), dtype=bool)
        on_hull[hull.simplices] = True
        faces = np.flatnonzero(on_hull)
        if len(faces) > _MASK_BITS:
            return None
        eq = hull.equations  # n . p + c = 0 on a hull facet: the polytope vertex is -n / c
        verts = eq[:, :-1] / -eq[:, -1:]
        facet_dual = dual[faces]  # distance of v to plane h: |p_h . v - 1| / |p_h|
        size = np.sqrt(np.einsum("ij,ij->i", facet_dual, facet_dual))
        tight = np.abs(verts @ facet_dual.T - 1.0) <= tol * size
        masks = tight @ _BITS[: len(faces)]
        norm2 = np.einsum("ij,ij->i", verts, verts).tolist()
        return cls(list(map(tuple, verts.tolist())), masks.tolist(), norm2)

    @classmethod
    def _from_dual_polygon(cls, dual: list[list[float]]) -> Polytope:
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

    def copy(self) -> Polytope:
        """An independent copy (cuts of one leave the other as it is)."""
        poly = Polytope(self.verts, self.masks, self.norm2)
        poly.blocked = list(self.blocked)
        return poly

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
        if len(a) == 2:
            return self._clip(a, b, tol)
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
                    norm2.append(sum(map(operator.mul, v, v)))
        self.verts, self.masks, self.blocked, self.norm2 = new_verts, new_masks, blocked, norm2
        self.reach2 = max(norm2)
        return True

    def _clip(self, a: list[float], b: float, tol: float) -> bool:
        """:meth:`cut` of a polygon (vertices counter-clockwise): one pass round its edges.

        Kept vertices stay in order; an edge from a vertex strictly inside to one strictly
        outside (or back) gives a new vertex on the plane in its place. About twice as fast
        as the general edge search over vertex pairs.
        """
        a0, a1 = a
        verts = self.verts
        d = [a0 * x + a1 * y - b for x, y in verts]
        if max(d) <= tol:
            return False
        masks, blocked, norm2 = self.masks, self.blocked, self.norm2
        used = 0
        for i, di in enumerate(d):
            if di <= tol:
                used |= masks[i]
        bit = ~used & (used + 1)  # lowest face bit no kept vertex uses
        new_verts: list[tuple[float, ...]] = []
        new_masks: list[int] = []
        new_blocked: list[bool] = []
        new_norm2: list[float] = []
        last = len(d) - 1
        for i, di in enumerate(d):
            j = i + 1 if i < last else 0
            dj = d[j]
            if di <= tol:
                new_verts.append(verts[i])
                new_masks.append(masks[i] | bit if di >= -tol else masks[i])
                new_blocked.append(blocked[i])
                new_norm2.append(norm2[i])
            if (di < -tol and dj > tol) or (di > tol and dj < -tol):
                # From the inner end, as cut does: the same vertex to the last bit.
                inner, outer, t = (i, j, di / (di - dj)) if di < 0 else (j, i, dj / (dj - di))
                (px, py), (qx, qy) = verts[inner], verts[outer]
                x, y = px + t * (qx - px), py + t * (qy - py)
                new_verts.append((x, y))
                new_masks.append((masks[i] & masks[j]) | bit)
                new_blocked.append(False)
                new_norm2.append(x * x + y * y)
        self.verts, self.masks, self.blocked, self.norm2 = (
            new_verts, new_masks, new_blocked, new_norm2
        )  # fmt: skip
        self.reach2 = max(new_norm2)
        return True
