"""Weight support: how heavy an object a grasp holds against a pull in each of six directions.

The Ferrari-Canny epsilon (:mod:`~sahgrasp.quality.wrench`) is the smallest wrench a grasp
resists in *any* direction, with torques scaled by the object's size; an object's weight is a
force through its centre of mass, and the grasps that fail a physics hold test mostly turn
under that force's moment about their contacts (docs/methods/physics.md). This module asks the
question
the hold test asks, as a linear program per pull direction.

Contact model. At contact ``i`` (point ``p_i``, outward unit normal ``n_i``) a soft finger
presses with a normal force ``N_i >= 0``, a friction force ``|f_t| <= mu N_i`` and a moment
about the normal ``|tau_i| <= kappa N_i`` (the torsional friction of a pressed contact patch of
radius ``a``, ``kappa = 2/3 mu a``; Howe and Cutkosky, "Practical force-motion models for
sliding manipulation", IJRR 1996). The cone is approximated from inside by the ``edges`` friction
edges ``e_ij = -n_i + mu t_ij`` and the two pure-torsion generators ``(-n_i, +-kappa n_i)``, each of
unit normal force, so that every generator combination is an admissible contact force: the test
never claims a hold the exact cone would not give. With generator weights ``g >= 0`` the contact
wrench about the centre of mass ``c`` is ``G g`` with columns ``(e, (p_i - c) x e + tau)``.

The pull. A force ``W d`` through ``c`` (``d`` one of +-x, +-y, +-z of the world, DexGraspNet's
and BODex's six pull directions) is resisted when ``G g = -(W d, 0)``. The smallest largest normal
force that resists a unit pull is the linear program

    t_d = min t  s.t.  G g = -(d, 0),  sum_j g_ij <= t for every contact i,  g >= 0  # Eq. (1)

and the grasp's weight support is ``s = min_d 1 / t_d`` [N of pull per N of finger force]: with
every finger pressing at most ``F`` newtons, it holds an object of mass ``m`` against the six
pulls of ``m g`` if ``m g <= s F``. ``s = 0`` when some pull cannot be resisted at all (two
point contacts without torsional friction, or contacts all on one side). ``s`` depends on the
grasp's geometry and the centre of mass only, not on the object's mass or size, so it ranks the
grasps of one object by how heavy a version of it they hold, and ``s F / (m g) >= 1`` is a cheap
screening test before a simulation (:func:`holds_weight`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import sparse
from scipy.optimize import linprog

from sahgrasp.quality.wrench import CONE_EDGES, FRICTION, WrenchError, cone_edges

__all__ = [
    "PATCH_RADIUS_M",
    "PULL_DIRECTIONS",
    "WeightSupport",
    "holds_weight",
    "weight_support",
    "weight_supports",
]

FloatArray = NDArray[np.float64]

PATCH_RADIUS_M = 0.0025
"""Default contact patch radius [m] of a fingertip (the hold test's ``patch_radius_m``)."""

PULL_DIRECTIONS: tuple[tuple[str, tuple[float, float, float]], ...] = (
    ("+x", (1.0, 0.0, 0.0)),
    ("-x", (-1.0, 0.0, 0.0)),
    ("+y", (0.0, 1.0, 0.0)),
    ("-y", (0.0, -1.0, 0.0)),
    ("+z", (0.0, 0.0, 1.0)),
    ("-z", (0.0, 0.0, -1.0)),
)
"""The six pulls, world axes (also those of the physics hold test, ``sim.settings.DIRECTIONS``)."""


@dataclass(frozen=True)
class WeightSupport:
    """The weight support of a grasp (module docstring).

    Attributes:
        support: ``min_d 1 / t_d`` of Eq. (1): the pull [N] the grasp resists in every direction
            per newton of the largest finger's normal force; 0 when some pull is not resisted.
        per_direction: ``1 / t_d`` for each of :data:`PULL_DIRECTIONS` (0: not resisted).
        weakest: The label of the direction of the smallest support.
    """

    support: float
    per_direction: tuple[float, ...]
    weakest: str


def _generators(
    points: FloatArray, normals: FloatArray, centre: FloatArray, mu: float, torsion_m: float,
    edges: int,
) -> FloatArray:  # fmt: skip
    """The generator wrenches (6, k * (edges + 2)) about ``centre``, contact by contact."""
    forces = cone_edges(normals, mu, edges)  # (k, edges, 3), unit normal component
    arms = (points - centre)[:, None, :]
    moments = np.cross(np.broadcast_to(arms, forces.shape), forces)
    columns = [np.concatenate([forces, moments], axis=2)]
    if torsion_m > 0.0:
        push = -normals[:, None, :]  # unit normal force, no friction
        spin = torsion_m * np.stack([-normals, normals], axis=1)  # +- kappa about the normal
        push2 = np.broadcast_to(push, spin.shape)
        columns.append(np.concatenate([push2, np.cross(arms, push2) + spin], axis=2))
    return np.concatenate(columns, axis=1).reshape(-1, 6).T


def weight_support(
    points_m: ArrayLike,
    normals: ArrayLike,
    centre_of_mass_m: ArrayLike,
    mu: float = FRICTION,
    patch_radius_m: float = PATCH_RADIUS_M,
    edges: int = CONE_EDGES,
) -> WeightSupport:
    """The weight support of contacts on an object (module docstring, Eq. (1)).

    Args:
        points_m: Contact points, world frame [m], (k, 3).
        normals: Outward unit object normals there, (k, 3).
        centre_of_mass_m: The object's centre of mass, world frame [m], (3,).
        mu: Coulomb friction coefficient (>= 0).
        patch_radius_m: Contact patch radius [m] of the soft-finger torsional friction
            ``2/3 mu a`` (0: point contacts).
        edges: Edges of each linearised friction cone (>= 3).

    Raises:
        WrenchError: Malformed arrays or parameters.
    """
    return weight_supports(
        [(points_m, normals)], centre_of_mass_m, mu, patch_radius_m=patch_radius_m, edges=edges
    )[0]


def weight_supports(
    contact_sets: Sequence[tuple[ArrayLike, ArrayLike]],
    centre_of_mass_m: ArrayLike,
    mu: float = FRICTION,
    patch_radius_m: float = PATCH_RADIUS_M,
    edges: int = CONE_EDGES,
) -> list[WeightSupport]:
    """The weight supports of several grasps of one object, in one linear program.

    Each grasp's six programs of Eq. (1) are independent blocks of one program, so many grasps
    cost one solver call instead of one each (the call's set-up costs more than a block).

    Args:
        contact_sets: Each grasp's contact points [m] and outward unit normals, (k, 3) each.
        centre_of_mass_m: The object's centre of mass, world frame [m], (3,).
        mu: Coulomb friction coefficient (>= 0).
        patch_radius_m: Contact patch radius [m] of the torsional friction (0: point contacts).
        edges: Edges of each linearised friction cone (>= 3).

    Raises:
        WrenchError: Malformed arrays or parameters.
    """
    centre = np.asarray(centre_of_mass_m, dtype=np.float64)
    if centre.shape != (3,):
        raise WrenchError(f"the centre of mass must be 3 numbers, got shape {centre.shape}")
    if not np.all(np.isfinite(centre)):
        raise WrenchError("contact points, normals and the centre of mass must be finite")
    if not (isinstance(patch_radius_m, int | float) and math.isfinite(patch_radius_m)
            and patch_radius_m >= 0.0):  # fmt: skip
        raise WrenchError(
            f"patch_radius_m must be a finite number >= 0 [m], got {patch_radius_m!r}"
        )
    torsion_m = 2.0 / 3.0 * mu * patch_radius_m if mu > 0 else 0.0
    pulls = np.hstack([np.array([axis for _, axis in PULL_DIRECTIONS]), np.zeros((6, 3))])
    count = len(PULL_DIRECTIONS)
    A_ub: list[Any] = []
    A_eq: list[Any] = []
    sizes: list[int] = []
    for points_m, normals in contact_sets:
        points, normal = _checked_contacts(points_m, normals)
        G = _generators(points, normal, centre, float(mu), torsion_m, edges)  # validates mu
        k = len(points)
        # Generator j belongs to contact owner[j] (contact-major: each contact's edges, torsion).
        owner = np.repeat(np.arange(k), G.shape[1] // k)
        n_g = G.shape[1]
        # Eq. (1) scaled by 1 / t: variables (g, lam), maximise lam = 1 / t_d with every
        # contact's normal force sum_j g_ij <= 1 and G g + lam (d, 0) = 0. Always feasible
        # (g = 0, lam = 0), so a pull the grasp cannot resist is lam = 0, not a failed program.
        ub = np.zeros((k, n_g + 1))
        ub[owner, np.arange(n_g)] = 1.0
        for d in range(count):
            A_ub.append(ub)
            A_eq.append(np.hstack([G, pulls[d][:, None]]))
        sizes.append(n_g + 1)
    if not sizes:
        return []
    # HiGHS's presolve costs more than it saves on these small blocks (same optima).
    cost = np.concatenate([np.r_[np.zeros(n - 1), -1.0] for n in sizes for _ in range(count)])
    out = linprog(cost, A_ub=sparse.block_diag(A_ub, format="csr"),
                  b_ub=np.ones(sum(a.shape[0] for a in A_ub)),
                  A_eq=sparse.block_diag(A_eq, format="csr"), b_eq=np.zeros(6 * len(A_eq)),
                  bounds=(0, None), method="highs",
                  options={"presolve": False})  # fmt: skip
    if out.status != 0:
        raise WrenchError(f"the weight-support program failed: {out.message}")
    ends = np.cumsum([n for n in sizes for _ in range(count)]) - 1
    lams = np.maximum(out.x[ends], 0.0).reshape(len(sizes), count)
    supports = []
    for values in lams:
        weakest = int(np.argmin(values))
        supports.append(
            WeightSupport(
                float(values[weakest]),
                tuple(float(v) for v in values),
                PULL_DIRECTIONS[weakest][0],
            )
        )
    return supports


def _checked_contacts(points_m: ArrayLike, normals: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """The contact points and unit normals as (k, 3) arrays, or raise :class:`WrenchError`."""
    points = np.asarray(points_m, dtype=np.float64)
    normal = np.asarray(normals, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise WrenchError(f"contact points must be a non-empty (k, 3) array, got {points.shape}")
    if normal.shape != points.shape:
        raise WrenchError(f"normals {normal.shape} must match the points {points.shape}")
    if not (np.all(np.isfinite(points)) and np.all(np.isfinite(normal))):
        raise WrenchError("contact points, normals and the centre of mass must be finite")
    lengths = np.linalg.norm(normal, axis=1)
    if np.any(np.abs(lengths - 1.0) > 1e-6):
        raise WrenchError("contact normals must be unit vectors")
    return points, normal


def holds_weight(
    support: float, mass_kg: float, squeeze_n: float, gravity_m_s2: float = 9.81
) -> bool:
    """Whether fingers pressing at most ``squeeze_n`` [N] resist the weight of ``mass_kg`` [kg].

    A cheap screening test before a simulation, ``mass_kg * gravity_m_s2 <= support *
    squeeze_n`` with ``support`` from :func:`weight_support`: it predicts the hold test's
    verdict without deciding it (loaded servoed fingers press harder than ``squeeze_n``, and
    the cones are approximated from inside).
    """
    for name, value in (("mass_kg", mass_kg), ("squeeze_n", squeeze_n),
                        ("gravity_m_s2", gravity_m_s2)):  # fmt: skip
        if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
            raise WrenchError(f"{name} must be a finite number > 0, got {value!r}")
    return mass_kg * gravity_m_s2 <= support * squeeze_n
