"""Principal hand motions (atlas paper, Section III): a PCA of sampled hand configurations.

The covariance of the samples ``X_h`` (one configuration per row) factors as ``T T^T = E S^2 E^T``;
the columns of ``E`` are the principal motions, sorted by decreasing variance ``S^2``. The ``s``
directions of least variance give the constraints ``E_s^T (x_h - x_1h) = 0`` of Eq. (13) that
reduce the feasible-grasp manifold to the set of relevant grasps (Eqs. (10)-(12)).

Shared by the planar hand (:mod:`sahgrasp.optimization.planar`) and the SAH grasp system
(:mod:`sahgrasp.optimization.grasp`); it knows nothing of either.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import PrincipalMotionsError

__all__ = ["PrincipalMotions", "principal_motions"]


@dataclass(frozen=True)
class PrincipalMotions:
    """PCA of hand configurations: directions ``E`` (columns) and variances ``S^2``.

    Attributes:
        mean: Average configuration, shape (h,).
        directions: ``E``, orthonormal columns sorted by decreasing variance, shape (h, h).
        variances: ``S^2`` in the same order, shape (h,).
    """

    mean: NDArray[np.float64]
    directions: NDArray[np.float64]
    variances: NDArray[np.float64]

    def constraints(self, s: int) -> NDArray[np.float64]:
        """``E_s^T``: the ``s`` directions of least variance, as rows, shape (s, h) (Eq. (10)).

        Raises:
            PrincipalMotionsError: ``s`` is not in ``[0, h)``.
        """
        h = len(self.variances)
        if not 0 <= s < h:
            raise PrincipalMotionsError(f"s = t - k must satisfy 0 <= s < h = {h}, got s = {s}")
        return self.directions[:, h - s :].T

    def retained_variance(self, s: int) -> float:
        """Share of the variance kept by the first ``h - s`` motions."""
        return float(self.variances[: len(self.variances) - s].sum() / self.variances.sum())


def principal_motions(samples: ArrayLike) -> PrincipalMotions:
    """PCA of hand configurations ``X_h``, one per row, shape (z, h): ``T T^T = E S^2 E^T``."""
    X = np.asarray(samples, dtype=np.float64)
    mean = X.mean(axis=0)
    centred = X - mean
    variances, E = np.linalg.eigh(centred.T @ centred / max(len(X) - 1, 1))
    order = np.argsort(variances)[::-1]
    return PrincipalMotions(mean, E[:, order], variances[order])
