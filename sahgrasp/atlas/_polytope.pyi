"""Type stub of the compiled chart polytopes (``_polytope.c``).

Arrays are C-contiguous float64; a bad one raises TypeError (not such an array, read-only where
written) or ValueError (its shape), naming it (``sahgrasp/_arrays.h``).
"""

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

MAX_FACES: int

def det_signs(a: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``out[b] = sign(det(a[b]))`` (1, -1, or 0 for a singular matrix) for a stack (B, n, n)."""

def min_singular_values(a: NDArray[np.float64], out: NDArray[np.float64]) -> None:
    """``out[b]``: the smallest singular value of ``a[b]`` for a stack (B, rows, k), rows >= k."""

def compatible(
    polys: Sequence[Polytope],
    centres: NDArray[np.float64],
    parent_centres: NDArray[np.float64],
    phi: NDArray[np.float64],
    parent_phi: NDArray[np.float64],
    vertices: NDArray[np.float64],
    r: float,
    r2: float,
    tol: float,
    threshold: float,
) -> list[int]:
    """The tries of a wave that can be added together, in order (``_Builder._compatible``).

    Try q (new centre ``centres[q]`` with tangent basis ``phi[q]``) comes from the picked vertex
    ``vertices[q]`` of the chart with polytope ``polys[q]``, centre ``parent_centres[q]`` and
    basis ``parent_phi[q]`` (C-contiguous float64 arrays (B, n), (B, n, k), (B, k)). It is kept
    unless the plane of an earlier kept try whose chart is alike (branch test, ``threshold`` on
    the squared smallest cosine) cuts off its vertex or makes another vertex the nearest one
    outside the ball of squared radius ``r2``.
    """

class Polytope:
    """Convex polytope in a chart's parameter space, vertex/face incidence as bit masks."""

    @classmethod
    def cube(cls, k: int, r: float) -> Polytope:
        """The k-cube ``[-r, r]^k`` enclosing the ball ``B_i`` (Fig. 6a); face 2d+s is x_d = -+r."""

    @classmethod
    def from_planes(
        cls,
        k: int,
        r: float,
        planes: Sequence[Sequence[float]],
        offsets: Sequence[float],
        tol: float,
    ) -> Polytope:
        """The cube ``[-r, r]^k`` cut by every half-space ``planes[h] . w <= offsets[h] (> 0)``."""

    def copy(self) -> Polytope:
        """An independent copy (cuts of one leave the other as it is)."""

    def to_bytes(self) -> bytes:
        """The whole state (vertices, norms, face masks, blocked flags), native byte order."""

    @classmethod
    def from_bytes(cls, data: bytes) -> Polytope:
        """The polytope whose :meth:`to_bytes` gave ``data``; ValueError if it did not."""

    def expandable(self, r2: float) -> int:
        """Index of the nearest unblocked vertex not inside the ball of squared radius ``r2``."""

    def cut(self, a: Sequence[float], b: float, tol: float) -> bool:
        """Intersect with the half-space ``a . w <= b``; True when a vertex was removed."""

    def vertex(self, i: int) -> tuple[float, ...]:
        """Vertex ``i``."""

    def vertex_norm2(self, i: int) -> float:
        """Squared norm of vertex ``i``."""

    def block(self, i: int) -> None:
        """Mark vertex ``i`` as blocked (an expansion from it failed)."""

    def index(self, vertex: Sequence[float]) -> int:
        """Index of the vertex equal to ``vertex``; ValueError if there is none."""

    def __len__(self) -> int: ...
    @property
    def verts(self) -> list[tuple[float, ...]]:
        """The vertices."""

    @property
    def masks(self) -> list[int]:
        """Faces through each vertex, one bit per face."""

    @property
    def norm2(self) -> list[float]:
        """Squared norm of each vertex."""

    @property
    def blocked(self) -> list[bool]:
        """Whether each vertex is blocked."""

    @property
    def reach2(self) -> float:
        """Squared norm of the farthest vertex."""

    @property
    def k(self) -> int:
        """Dimension of the parameter space."""
