"""Ball queries over the growing set of chart centres."""

from __future__ import annotations

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
    ) -> list[IndexArray]:
        """Per row of ``xs`` (A, n): indices ``< count`` of ``points`` closer than ``radius``.

        The k-d tree answers for all rows in one call; the unindexed tail is scanned directly.
        """
        pending = points[self._n_tree : count][None] - xs[:, None]
        close = (pending * pending).sum(axis=2) < radius**2
        tails = [self._n_tree + np.flatnonzero(row) for row in close]
        if self._tree is None:
            return tails
        found = self._tree.query_ball_point(xs, radius, return_sorted=False)
        return [
            np.concatenate((np.asarray(f, np.int64), t)) for f, t in zip(found, tails, strict=True)
        ]

    def added(self, points: FloatArray, count: int) -> None:
        """Note that ``count`` points exist; rebuild the tree when the unindexed tail is long."""
        if count - self._n_tree > max(32, count // 16):
            self._tree = cKDTree(points[:count])
            self._n_tree = count
