"""Force closure and the Ferrari-Canny epsilon of a set of point contacts.

The contact model is the hard finger (a point contact with Coulomb friction): at contact ``i``,
with outward unit normal ``n_i`` of the object, the finger may push with any force in the
friction cone ``{f : |f_t| <= mu f_n}`` about the inward normal ``-n_i``. The cone is linearised
by ``edges`` unit-normal-component edge forces (:data:`CONE_EDGES` by default)::

    f_ij = -n_i + mu (cos(2 pi j / m) t1_i + sin(2 pi j / m) t2_i),  j = 0 .. m-1

so that every force of the linearised cone with a normal component ``f_n`` is a non-negative
combination of its edges summing to ``f_n``. Each edge gives a primitive wrench

    w_ij = (f_ij, (p_i - c) x f_ij / rho)

with ``c`` the object's reference point (its centroid) and ``rho`` the object's radius about it
(the largest distance from ``c`` to its surface): torques divided by ``rho`` have the unit of a
force, and the quality does not change when the object and its grasp are scaled together
(Ferrari and Canny, "Planning optimal grasps", ICRA 1992, Section 3; the same convention as
GraspIt!'s radius-scaled torques).

Grasp wrench spaces (Ferrari and Canny, ibid.):

* L1 (total normal force at most 1): ``W_1 = ConvexHull(U_i {w_ij})``;
* L-infinity (each contact's normal force at most 1):
  ``W_inf = ConvexHull(sum_i ({0} U {w_ij}_j))``, the Minkowski sum of the contacts' edge sets
  with the zero wrench (a contact may push less than 1), ``(m + 1)^c`` points for ``c``
  contacts. Its hull grows fast with ``m`` and ``c`` (in six dimensions, hundreds of thousands of
  facets for four contacts of eight edges), so the L-infinity epsilon uses a pyramid of
  :data:`LINF_CONE_EDGES` edges by default; ``W_1`` lies inside ``W_inf``, so the L-infinity
  epsilon is never below the L1 epsilon of the same cone.

The grasp is in force closure when the origin lies strictly inside ``W_1`` (it then lies inside
``W_inf`` too); the epsilon quality is the distance from the origin to the nearest facet of the
hull, the radius of the largest origin-centred ball in it (0 when not in force closure). The hulls
are computed by Qhull (``scipy.spatial.ConvexHull``); a set of wrenches that spans fewer than six
dimensions (two contacts always do: nothing resists a torque about the line through them) is not
force closure, reported as such rather than as a Qhull error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull, QhullError

from sahgrasp.core.errors import SahGraspError

__all__ = [
    "CONE_EDGES",
    "FRICTION",
    "LINF_CONE_EDGES",
    "MAX_MINKOWSKI_POINTS",
    "WrenchError",
    "WrenchQuality",
    "cone_edges",
    "epsilon",
    "force_closure",
    "grasp_quality",
    "primitive_wrenches",
]

FloatArray = NDArray[np.float64]

FRICTION = 0.5
"""Default Coulomb friction coefficient ``mu`` between fingertip and object."""
CONE_EDGES = 8
"""Default number of edges of the linearised friction cone (L1 wrench space)."""
LINF_CONE_EDGES = 3
"""Default number of cone edges of the L-infinity wrench space (module docstring)."""
MAX_MINKOWSKI_POINTS = 200_000
"""Largest point count of the L-infinity Minkowski sum accepted (``edges ** contacts``)."""
_INSIDE_TOL = 1e-9
"""The origin counts as strictly inside when it is at least this far inside every facet [1]."""
_RANK_TOL = 1e-9
"""Relative singular value below which the wrenches span fewer than six dimensions."""
_NNLS_TOL = 1e-10
"""Relative residual of :func:`force_closure`'s least squares counted as an exact solution."""


class WrenchError(SahGraspError):
    """Contacts or parameters of a wrench-space computation are malformed."""


@dataclass(frozen=True)
class WrenchQuality:
    """Force closure and epsilon qualities of a contact set.

    Attributes:
        force_closure: The origin lies strictly inside the grasp wrench space.
        epsilon_l1: Ferrari-Canny epsilon of the L1 wrench space (0 without force closure) [1].
        epsilon_linf: Epsilon of the L-infinity wrench space (0 without force closure), or None
            when it was not computed [1].
    """

    force_closure: bool
    epsilon_l1: float
    epsilon_linf: float | None = None


def _checked(points_m: ArrayLike, normals: ArrayLike) -> tuple[FloatArray, FloatArray]:
    points = np.asarray(points_m, dtype=np.float64)
    normal = np.asarray(normals, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or normal.shape != points.shape:
        raise WrenchError(
            f"contact points and normals must both have shape (N, 3), got {points.shape} and "
            f"{normal.shape}"
        )
    if len(points) == 0:
        raise WrenchError("a wrench space needs at least one contact")
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(normal))):
        raise WrenchError("contact points and normals must be finite")
    lengths = np.linalg.norm(normal, axis=1)
    if np.any(np.abs(lengths - 1.0) > 1e-6):
        raise WrenchError(f"contact normals must be unit vectors, lengths {lengths.tolist()}")
    return points, normal


def cone_edges(normals: ArrayLike, mu: float = FRICTION, edges: int = CONE_EDGES) -> FloatArray:
    """The edge forces (N, edges, 3) of the linearised friction cones about ``-normals``.

    Args:
        normals: Outward unit normals of the object at the contacts, (N, 3).
        mu: Coulomb friction coefficient (>= 0).
        edges: Edges per cone (>= 3).
    """
    if not (isinstance(mu, int | float) and math.isfinite(mu) and mu >= 0.0):
        raise WrenchError(f"friction mu must be a finite number >= 0, got {mu!r}")
    if isinstance(edges, bool) or not isinstance(edges, int) or edges < 3:
        raise WrenchError(f"a friction cone needs an integer number of edges >= 3, got {edges!r}")
    n = np.asarray(normals, dtype=np.float64)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = _cross(n, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = _cross(n, t1)
    angles = 2.0 * math.pi * np.arange(edges) / edges
    tangential = (
        np.cos(angles)[None, :, None] * t1[:, None] + np.sin(angles)[None, :, None] * t2[:, None]
    )
    return -n[:, None, :] + mu * tangential


def primitive_wrenches(
    points_m: ArrayLike,
    normals: ArrayLike,
    centre_m: ArrayLike,
    radius_m: float,
    mu: float = FRICTION,
    edges: int = CONE_EDGES,
) -> FloatArray:
    """The primitive wrenches ``w_ij`` (N, edges, 6) of the contacts (module docstring).

    Args:
        points_m: Contact points on the object [m], (N, 3).
        normals: Outward unit normals there, (N, 3).
        centre_m: The torque reference point (the object's centroid) [m], (3,).
        radius_m: The object's radius about it, the torque scale [m] (> 0).
        mu: Coulomb friction coefficient.
        edges: Edges per friction cone.

    Raises:
        WrenchError: Malformed arrays or parameters.
    """
    points, normal = _checked(points_m, normals)
    centre = np.asarray(centre_m, dtype=np.float64)
    if centre.shape != (3,) or not np.all(np.isfinite(centre)):
        raise WrenchError(f"the torque reference point must be 3 finite numbers, got {centre_m!r}")
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise WrenchError(f"the torque scale radius must be finite and > 0 [m], got {radius_m!r}")
    forces = cone_edges(normal, mu, edges)
    arms = (points - centre)[:, None, :] / radius_m
    return np.concatenate([forces, _cross(np.broadcast_to(arms, forces.shape), forces)], axis=2)


def _cross(a: FloatArray, b: FloatArray) -> FloatArray:
    """``np.cross`` of two (..., 3) arrays: the same arithmetic, without its set-up.

    The planner asks for the wrenches of a few contacts thousands of times per object, where
    ``np.cross``'s axis handling costs more than its products.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def force_closure(wrenches: ArrayLike) -> bool:
    """Whether the origin lies in the interior of ``ConvexHull(wrenches)``, without the hull.

    The interior of the hull of points spanning six dimensions is the set of their combinations
    with every weight strictly positive, so the origin is inside exactly when the wrenches span
    six dimensions and ``sum_i lambda_i w_i = 0`` has a solution with every ``lambda_i >= 1``
    (any strictly positive solution, scaled). With ``lambda = 1 + x``, that is a non-negative
    least-squares problem ``min ||W x + W 1||, x >= 0`` (scipy's ``nnls``) whose residual is 0
    exactly when a solution exists: tens of microseconds, against milliseconds for the hull.
    A contact set this calls force closure may still have an epsilon of 0 by :func:`epsilon`'s
    margin (the origin within 1e-9 of a facet).

    Args:
        wrenches: Points (K, 6).
    """
    from scipy.optimize import nnls

    w = np.asarray(wrenches, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 6 or len(w) < 7 or not np.all(np.isfinite(w)):
        return False
    singular = np.linalg.svd(w, compute_uv=False)
    if singular[-1] <= _RANK_TOL * max(singular[0], 1e-300):
        return False  # flat: fewer than six dimensions
    target = -w.sum(axis=0)
    _, residual = nnls(w.T, target)
    return bool(residual <= _NNLS_TOL * max(float(np.linalg.norm(target)), singular[0]))


def epsilon(wrenches: ArrayLike, exact: bool = True) -> float:
    """Distance from the origin to the boundary of ``ConvexHull(wrenches)``; 0 if not inside.

    Args:
        wrenches: Points (K, 6) spanning the wrench space.
        exact: Where Qhull without merging meets a precision problem (:func:`_hull_distance`),
            it merges coplanar facets exactly (option ``Qx``); False joggles the input instead
            (``QJ``: about twice as fast on cone edges, whose points are coplanar in groups,
            and within about 1e-10 of the exact distance), for screening.

    Returns:
        The radius of the largest origin-centred ball inside the hull when the origin is strictly
        inside it (by more than 1e-9), else 0.0 (including hulls of fewer than six dimensions).
    """
    w = np.asarray(wrenches, dtype=np.float64)
    if w.ndim != 2 or w.shape[1] != 6 or len(w) < 7:
        return 0.0
    singular = np.linalg.svd(w, compute_uv=False)
    if singular[-1] <= _RANK_TOL * max(singular[0], 1e-300):
        return 0.0  # flat: a hull of fewer than six dimensions holds no 6-D ball
    distance = _hull_distance(w, "Qx" if exact else "QJ")
    return distance if distance > _INSIDE_TOL else 0.0


def _hull_distance(w: FloatArray, merge: str) -> float:
    """The origin's distance to the nearest facet plane of ``ConvexHull(w)`` (0: no hull).

    Qhull first without merging (``Q0``): several times faster than merging coplanar facets
    (``Qx``) or joggling (``QJ``), and it stops with a precision error rather than return a
    concave ridge or a flipped facet, so a hull it returns has the merged hull's facet planes
    (its coplanar facets are left split, which moves no plane). On that error, most common on
    the L-infinity Minkowski sums, the hull is computed again with ``merge``.
    """
    for options in ("Q0", merge):
        try:
            hull = ConvexHull(w, qhull_options=options)
        except QhullError:  # with merge: a (nearly) flat set Qhull cannot triangulate
            continue
        # Facet i: normal . x + offset <= 0 inside, unit normal: the origin's distance is -offset.
        return float(-hull.equations[:, -1].max())
    return 0.0


def grasp_quality(
    points_m: ArrayLike,
    normals: ArrayLike,
    centre_m: ArrayLike,
    radius_m: float,
    mu: float = FRICTION,
    edges: int = CONE_EDGES,
    linf: bool = True,
    linf_edges: int = LINF_CONE_EDGES,
) -> WrenchQuality:
    """Force closure and the Ferrari-Canny epsilons of point contacts on an object.

    Args:
        points_m: Contact points [m], (N, 3).
        normals: Outward unit object normals at them, (N, 3).
        centre_m: The object's centroid, the torque reference point [m].
        radius_m: The object's radius about the centroid, the torque scale [m].
        mu: Coulomb friction coefficient (default :data:`FRICTION`).
        edges: Friction cone edges (default :data:`CONE_EDGES`).
        linf: Also compute the L-infinity epsilon (``(linf_edges + 1) ** N`` points: the
            costlier one).
        linf_edges: Friction cone edges of the L-infinity wrench space.

    Raises:
        WrenchError: Malformed inputs, or an L-infinity sum of more than
            :data:`MAX_MINKOWSKI_POINTS` points.
    """
    w = primitive_wrenches(points_m, normals, centre_m, radius_m, mu, edges)
    eps1 = epsilon(w.reshape(-1, 6))
    if not linf:
        return WrenchQuality(eps1 > 0.0, eps1, None)
    if eps1 == 0.0:
        return WrenchQuality(False, 0.0, 0.0)
    w_inf = primitive_wrenches(points_m, normals, centre_m, radius_m, mu, linf_edges)
    return WrenchQuality(True, eps1, epsilon(_minkowski_sum(w_inf)))


def _minkowski_sum(w: FloatArray) -> FloatArray:
    """All sums of one edge wrench or zero per contact, ((edges + 1) ** N, 6)."""
    count = (w.shape[1] + 1) ** w.shape[0]
    if count > MAX_MINKOWSKI_POINTS:
        raise WrenchError(
            f"the L-infinity wrench space of {w.shape[0]} contacts with {w.shape[1]} cone edges "
            f"has {count} points (more than {MAX_MINKOWSKI_POINTS}); use fewer edges or linf=False"
        )
    total = np.zeros((1, 6))
    for contact in w:
        # Each contact adds a normal force between 0 and 1: its edges and the zero wrench.
        choices = np.vstack([np.zeros((1, 6)), contact])
        total = (total[:, None, :] + choices[None, :, :]).reshape(-1, 6)
    return total
