"""Type stub of the compiled IK loop (``_lm.c``).

Arrays are C-contiguous float64 (``NDArray[np.float64]``) or int64 (``NDArray[np.int64]``); a bad
one raises TypeError (not such an array) or ValueError (its shape or values), naming it
(``sahgrasp/_arrays.h``). The constants are the C enums' values: ``sahgrasp.ik.compiled`` reads
them, never a copy.
"""

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

CONVERGED: int
NO_PROGRESS: int
MAX_ITERATIONS: int
SHAPE_POINT: int
SHAPE_BOX: int
SHAPE_CYLINDER: int
SHAPE_ELLIPSOID: int
SHAPE_CONVEX: int
FIXED_JOINT: int

def rigid_key(
    points: NDArray[np.float64],
    normals: NDArray[np.float64],
    normal_scale: float,
    out: NDArray[np.float64],
) -> None: ...

class Pieces:
    def __init__(
        self,
        *,
        kinds: NDArray[np.int64],
        placements: NDArray[np.float64],
        sizes: NDArray[np.float64],
        balls: NDArray[np.float64],
        vertex_start: NDArray[np.int64],
        vertices: NDArray[np.float64],
        first: NDArray[np.int64],
        neighbours: NDArray[np.int64],
        cell_balls: NDArray[np.float64],
        cell_start: NDArray[np.int64],
        cell_members: NDArray[np.int64],
    ) -> None: ...

class Tree:
    shape_count: int
    pair_count: int
    def __init__(
        self,
        *,
        parents: NDArray[np.int64],
        placements: NDArray[np.float64],
        axes: NDArray[np.float64],
        prismatic: NDArray[np.int64],
        q_index: NDArray[np.int64],
        v_index: NDArray[np.int64],
        scale: NDArray[np.float64],
        offset: NDArray[np.float64],
        yaw: NDArray[np.int64],
        radius: float,
        lower: NDArray[np.float64],
        upper: NDArray[np.float64],
        nq: int,
        nv: int,
    ) -> None: ...
    def solve(
        self,
        q: NDArray[np.float64],
        target: NDArray[np.float64],
        fingers: NDArray[np.int64],
        max_iterations: int,
        refine_m: float,
        d_min_m: float,
        stall: int,
        history: Callable[[], object] | None,
    ) -> tuple[int, int, float]: ...
    def stack(
        self,
        q: NDArray[np.float64],
        fingers: NDArray[np.int64],
        stack_out: NDArray[np.float64],
        jacobian_out: NDArray[np.float64] | None,
    ) -> None: ...
    def errors(
        self,
        q: NDArray[np.float64],
        target: NDArray[np.float64],
        fingers: NDArray[np.int64],
        out: NDArray[np.float64],
    ) -> None: ...
    def integrate(
        self, q: NDArray[np.float64], v: NDArray[np.float64], out: NDArray[np.float64], clamp: bool
    ) -> None: ...
    def align(
        self, q: NDArray[np.float64], goal: NDArray[np.float64], fingers: NDArray[np.int64]
    ) -> None: ...
    def repair(
        self,
        q: NDArray[np.float64],
        target: NDArray[np.float64],
        fingers: NDArray[np.int64],
        joints: NDArray[np.int64],
        points: NDArray[np.float64],
        normals: NDArray[np.float64],
        depths: NDArray[np.float64],
        out: NDArray[np.float64],
    ) -> bool: ...
    def set_shapes(
        self,
        *,
        joints: NDArray[np.int64],
        placements: NDArray[np.float64],
        kinds: NDArray[np.int64],
        sizes: NDArray[np.float64],
        balls: NDArray[np.float64],
        pairs: NDArray[np.int64],
    ) -> None: ...
    def pairs_within(
        self, q: NDArray[np.float64], margin_m: float, out: NDArray[np.int64]
    ) -> int: ...
    def object_clearance(
        self,
        pieces: Pieces,
        q: NDArray[np.float64],
        T_world_object: NDArray[np.float64],
        thresholds: NDArray[np.float64],
    ) -> tuple[bool, float, int]: ...
    def shapes_near(
        self,
        pieces: Pieces,
        q: NDArray[np.float64],
        T_world_object: NDArray[np.float64],
        thresholds: NDArray[np.float64],
        out: NDArray[np.int64],
    ) -> int: ...
