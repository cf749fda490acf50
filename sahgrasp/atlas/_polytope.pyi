"""Type stub of the compiled chart polytopes (``_polytope.c``)."""

from collections.abc import Sequence

MAX_FACES: int

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
