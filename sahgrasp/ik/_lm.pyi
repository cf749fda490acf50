"""Type stub of the compiled IK loop (``_lm.c``)."""

from collections.abc import Callable

from numpy.typing import NDArray

CONVERGED: int
NO_PROGRESS: int
MAX_ITERATIONS: int

def rigid_key(points: NDArray, normals: NDArray, normal_scale: float, out: NDArray) -> None: ...

class Pieces:
    def __init__(
        self,
        kinds: NDArray,
        placements: NDArray,
        sizes: NDArray,
        balls: NDArray,
        vertex_start: NDArray,
        vertices: NDArray,
        first: NDArray,
        neighbours: NDArray,
        cell_balls: NDArray,
        cell_start: NDArray,
        cell_members: NDArray,
    ) -> None: ...

class Tree:
    shape_count: int
    pair_count: int
    def __init__(
        self,
        parents: NDArray,
        placements: NDArray,
        axes: NDArray,
        prismatic: NDArray,
        q_index: NDArray,
        v_index: NDArray,
        scale: NDArray,
        offset: NDArray,
        yaw: NDArray,
        radius: float,
        lower: NDArray,
        upper: NDArray,
        nq: int,
        nv: int,
    ) -> None: ...
    def solve(
        self,
        q: NDArray,
        target: NDArray,
        fingers: NDArray,
        max_iterations: int,
        refine_m: float,
        d_min_m: float,
        stall: int,
        history: Callable[[], object] | None,
    ) -> tuple[int, int, float]: ...
    def stack(
        self, q: NDArray, fingers: NDArray, stack_out: NDArray, jacobian_out: NDArray | None
    ) -> None: ...
    def errors(self, q: NDArray, target: NDArray, fingers: NDArray, out: NDArray) -> None: ...
    def integrate(self, q: NDArray, v: NDArray, out: NDArray, clamp: bool) -> None: ...
    def align(self, q: NDArray, goal: NDArray, fingers: NDArray) -> None: ...
    def repair(
        self,
        q: NDArray,
        target: NDArray,
        fingers: NDArray,
        joints: NDArray,
        points: NDArray,
        normals: NDArray,
        depths: NDArray,
        out: NDArray,
    ) -> bool: ...
    def set_shapes(
        self,
        joints: NDArray,
        placements: NDArray,
        kinds: NDArray,
        sizes: NDArray,
        balls: NDArray,
        pairs: NDArray,
    ) -> None: ...
    def pairs_within(self, q: NDArray, margin_m: float, out: NDArray) -> int: ...
    def object_clearance(
        self, pieces: Pieces, q: NDArray, T_world_object: NDArray, thresholds: NDArray
    ) -> tuple[bool, float, int]: ...
    def shapes_near(
        self, pieces: Pieces, q: NDArray, T_world_object: NDArray, thresholds: NDArray, out: NDArray
    ) -> int: ...
