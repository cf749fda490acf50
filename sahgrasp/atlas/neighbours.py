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

    def query(self, points: FloatArray, count: int, x: FloatArray, radius: float) -> IndexArray:
        """Indices ``< count`` of ``points`` closer than ``radius`` to ``x``."""
        pending = points[self._n_tree : count] - x
        near = self._n_tree + np.flatnonzero((pending * pending).sum(axis=1) < radius**2)
        if self._tree is None:
            return near
        found = np.asarray(self._tree.query_ball_point(x, radius, return_sorted=False), np.int64)
        return np.concatenate((found, near))

    def added(self, points: FloatArray, count: int) -> None:
        """Note that ``count`` points exist; rebuild the tree when the unindexed tail is long."""
        if count - self._n_tree > max(32, count // 16):
            self._tree = cKDTree(points[:count])
            self._n_tree = count
