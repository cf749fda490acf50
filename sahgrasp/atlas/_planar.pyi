"""Type stub of the planar hand's compiled Jacobian (``_planar.c``).

Arrays are C-contiguous float64 (``where``: int64); a bad one raises TypeError (not such an
array, read-only where written) or ValueError (its shape or values), naming it
(``sahgrasp/_arrays.h``).
"""

import numpy as np
from numpy.typing import NDArray

def jacobian(
    x: NDArray[np.float64],
    constant: NDArray[np.float64],
    where: NDArray[np.int64],
    radii: NDArray[np.float64],
    rates: NDArray[np.float64],
    out: NDArray[np.float64],
) -> None:
    """The Jacobian of ``PlanarGraspProblem.F`` at each row of ``x`` (B, 19), into ``out``.

    ``out[b]`` (16 + s, 19) is the flattened ``constant`` with the 29 variable entries of the
    grasp equations and then ``rates * (angle gradients)`` (``rates`` (s, 12): Eq. (13)) put at
    ``where`` (29 + 12 s flat indices); ``radii`` are the object's circle radii (3,).
    """

def features(
    x: NDArray[np.float64],
    reference: NDArray[np.float64],
    out: NDArray[np.float64],
    cosines: NDArray[np.float64],
) -> None:
    """The terms ``PlanarGraspProblem.F`` is linear in, at each row of ``x`` (B, 19), into ``out``.

    ``out[b]`` (56): ``x``, its squares, ``cos u_i``, ``sin u_i``, ``cos u_i v_{i,2,y}``,
    ``sin u_i v_{i,2,x}``, then per phalanx ``p x v`` with ``p`` its vector in ``reference``;
    ``cosines[b]`` (6) gets ``p . v``, so that ``arctan2(out[b, 50:], cosines[b])`` are the
    phalanx turns from ``reference``.
    """
