"""Type stub of the compiled part of the quality indices (``_quality.c``).

Arrays are C-contiguous float64; a bad one raises TypeError (not such an
array, read-only where written) or ValueError (its shape or values), naming it
(``sahgrasp/_arrays.h``).
"""

import numpy as np
from numpy.typing import NDArray

def orthogonal_tail(
    h: NDArray[np.float64], tau: NDArray[np.float64], out: NDArray[np.float64]
) -> None:
    """The last ``n - m`` columns of each Q (B, n, n - m), into ``out``.

    ``h`` (B, m, n) and ``tau`` (B, m) are ``numpy.linalg.qr(a, mode="raw")`` of a stack ``a``
    (B, n, m), ``1 <= m < n``: reflector i is ``(0, ..., 0, 1, h[b, i, i + 1:])``.
    """

def semi_axes(
    actuated: NDArray[np.float64],
    obj: NDArray[np.float64],
    out: NDArray[np.float64],
    rank_tol: float,
) -> None:
    """Semi-axes (B, o), largest first, of the ellipsoids ``{obj tau : |actuated tau| <= 1}``.

    ``actuated`` (B, a, t), ``obj`` (B, o, t); all zero where the smallest singular value of
    ``actuated`` (of its thin SVD) is at most ``rank_tol`` times its largest.
    """
