"""Ball queries over the growing set of chart centres."""

from __future__ import annotations

import itertools

import numpy as np
from scipy.spatial import cKDTree

from sahgrasp.atlas.model import FloatArray, IndexArray

__all__ = ["NeighbourIndex"]


class NeighbourIndex:
    """Ball queries over a growing point set, without quadratic cost."""

    __slots__ = ("_n_tree", "_tree")

    def __init__(self) -> None:
        self._tree: cKDTree | None = None
        self._n_tree = 0

    def query(
        self, points: FloatArray, count: int, xs: FloatArray, radius: float
    ) -> tuple[IndexArray, IndexArray]:
        """Pairs (row of ``xs`` (A, n), index ``< count`` of ``points``) closer than ``radius``.

        The k-d tree answers for all rows in one call; the unindexed tail is scanned directly.
        The tree's pairs come first, then the tail's, each group in row order: a stable sort by
        row (as the atlas builder's ``add_charts`` makes, in :mod:`sahgrasp.atlas.builder`)
        lists every row's tree hits, then its tail.
        """
        pending = points[self._n_tree : count][None] - xs[:, None]
        rows, cols = np.nonzero((pending * pending).sum(axis=2) < radius**2)
        cols += self._n_tree
        if self._tree is None:
            return rows, cols
        found = self._tree.query_ball_point(xs, radius, return_sorted=False)
        sizes = [len(f) for f in found]
        hits = np.fromiter(itertools.chain.from_iterable(found), np.int64, sum(sizes))
        owners = np.repeat(np.arange(len(xs)), sizes)
        return np.concatenate((owners, rows)), np.concatenate((hits, cols))

    @property
    def indexed(self) -> int:
        """How many of the first points the k-d tree holds."""
        return self._n_tree

    def restore(self, points: FloatArray, indexed: int) -> None:
        """Index the first ``indexed`` points, as an index that had them indexed did."""
        self._tree = cKDTree(points[:indexed]) if indexed else None
        self._n_tree = indexed

    def added(self, points: FloatArray, count: int) -> None:
        """Note that ``count`` points exist; rebuild the tree when the unindexed tail is long."""
        if count - self._n_tree > max(32, count // 16):
            self._tree = cKDTree(points[:count])
            self._n_tree = count
