"""A smooth local model of a mesh around a contact: a height polynomial over the tangent plane.

The atlas's grasp equations need, at every contact, a surface point ``O(u, v)`` and outward normal
``M(u, v)`` with exact first derivatives (atlas paper, Eqs. (3)-(4), (7)-(8)); a triangle mesh has
neither (its normal jumps at every edge). Near a contact point ``p_0`` with outward normal ``n_0``,
a surface is the graph of a height function over its tangent plane (a Monge patch). With an
orthonormal frame ``(e_1, e_2, n_0)``::

    O(u, v) = p_0 + u e_1 + v e_2 + h(u, v) n_0                                    (M1)
    M(u, v) = (n_0 - h_u e_1 - h_v e_2) / sqrt(1 + h_u^2 + h_v^2)                  (M2)

with ``h`` a bivariate polynomial of degree ``d`` (4 by default) fitted to the mesh by weighted
least squares, the classical way of estimating a surface's local differential geometry from a
mesh (Cazals and Pouget, "Estimating differential quantities using polynomial fitting of
osculating jets", Computer Aided Geometric Design 22(2), 2005)::

    min_c  sum_i w_i (h_c(u_i, v_i) - z_i)^2,  w_i = a_i exp(-(u_i^2 + v_i^2) / s^2)    (M3)

over sample points ``(u_i, v_i, z_i)`` of the mesh in the local frame: the vertices and points of
every triangle facing ``n_0`` (normal within 60 degrees) within the fitting radius, each weighted
by the area ``a_i`` it stands for and by a Gaussian of width ``s`` = the patch's half width. The
model is a polynomial, so it is smooth and its derivatives are exact: ``dO/du = e_1 + h_u n_0``,
and with ``g = n_0 - h_u e_1 - h_v e_2``, ``dM/du = (g_u - M (M . g_u)) / |g|`` where
``g_u = -h_uu e_1 - h_uv e_2`` (and likewise in ``v``).

The patch is the square ``|u|, |v| <= a``. Its half width ``a`` is the largest of a few sizes (from
``max_half_width_m`` down to ``min_half_width_m``) at which the model stays within
``tolerance_m`` of the mesh on a 9 x 9 grid of the square (distance to the closest point of the
mesh) and faces the same way (model normal within 90 degrees of the closest face's): the model is
trusted only where it is checked. The patch keeps the errors it was accepted with
(``fit_error_m``, ``normal_error_rad``: the largest angle between the model's normal and the
normal of the closest mesh face, which on a coarse mesh includes the facets' own kinks).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import SahGraspError
from sahgrasp.core.frames import FloatArray, as_placement
from sahgrasp.objects.surfaces import SurfaceJet

__all__ = ["DEGREE", "MeshPatch", "SurfaceModelError", "fit_mesh_patch"]

DEGREE = 4
"""Degree of the height polynomial ``h`` (15 coefficients)."""

_FACING_COS = 0.5  # samples of triangles whose normal is within 60 degrees of n_0
_FIT_RADIUS = 1.6  # fitting radius, times the half width a (the square's corners at 1.41 a)
_SHRINK = 0.75  # next half width tried when the model strays from the mesh
_CHECK_GRID = 9  # points per side of the grid the model is checked on


class SurfaceModelError(SahGraspError):
    """No smooth local model of the mesh fits around a contact.

    The mesh there is too rough, has a sharp edge or a corner, or too few triangles face the
    contact's normal.
    """


_FAR = 1e3
"""Largest ``|u| / a`` and ``|v| / a`` at which :meth:`MeshPatch.height` evaluates the model."""


@functools.cache
def _exponents(degree: int) -> tuple[tuple[int, int], ...]:
    return tuple((i, total - i) for total in range(degree + 1) for i in range(total, -1, -1))


@dataclass(frozen=True, eq=False)
class MeshPatch:
    """A :class:`~sahgrasp.objects.patches.ContactRegion` on a mesh: Eqs. (M1)-(M2) above.

    Attributes:
        name: Region name.
        origin: ``p_0`` [m], in the object frame, shape (3,).
        frame: Columns ``e_1, e_2, n_0`` (object frame), shape (3, 3).
        coefficients: ``c`` of ``h(u, v) = sum c_j (u / a)^i (v / a)^l`` [m], in the order of
            ``_exponents(degree)``.
        half_width_m: ``a``: the patch is ``|u|, |v| <= a`` [m].
        degree: Degree of ``h``.
        nominal_uv: Parameters of the start contact [m].
        fit_error_m: Largest distance from the model to the mesh over the patch [m].
        normal_error_rad: Largest angle between the model's normal and the closest mesh face's.
        placement: Placement of the object frame in the reporting frame (4x4).
    """

    name: str
    origin: FloatArray
    frame: FloatArray
    coefficients: FloatArray
    half_width_m: float
    degree: int
    nominal_uv: tuple[float, float]
    fit_error_m: float
    normal_error_rad: float
    placement: FloatArray = field(default_factory=lambda: as_placement(np.eye(4)))

    def __post_init__(self) -> None:
        object.__setattr__(self, "placement", as_placement(self.placement))

    @property
    def lower(self) -> FloatArray:
        """``(-a, -a)`` [m]."""
        return np.full(2, -self.half_width_m)

    @property
    def upper(self) -> FloatArray:
        """``(a, a)`` [m]."""
        return np.full(2, self.half_width_m)

    @property
    def nominal(self) -> FloatArray:
        """``nominal_uv`` as an array [m]."""
        return np.array(self.nominal_uv, dtype=np.float64)

    def height(self, u: float, v: float) -> tuple[float, float, float, float, float, float]:
        """``h`` and its derivatives ``h_u, h_v, h_uu, h_uv, h_vv`` at ``(u, v)`` [m]."""
        a = self.half_width_m
        # A diverging Newton step may ask for the model far outside its square, where it means
        # nothing: the polynomial is held at |s|, |t| <= 1e3 there, never overflowing.
        s, t = min(max(u / a, -_FAR), _FAR), min(max(v / a, -_FAR), _FAR)
        h = hu = hv = huu = huv = hvv = 0.0
        for c, (i, j) in zip(self.coefficients.tolist(), _exponents(self.degree), strict=True):
            si = s**i
            tj = t**j
            h += c * si * tj
            if i:
                dsi = i * s ** (i - 1)
                hu += c * dsi * tj
                if i > 1:
                    huu += c * i * (i - 1) * s ** (i - 2) * tj
                if j:
                    huv += c * dsi * j * t ** (j - 1)
            if j:
                hv += c * si * j * t ** (j - 1)
                if j > 1:
                    hvv += c * si * j * (j - 1) * t ** (j - 2)
        return h, hu / a, hv / a, huu / a**2, huv / a**2, hvv / a**2

    def evaluate(self, params: ArrayLike) -> SurfaceJet:
        """Point, outward normal and their (3, 2) Jacobians at ``params = (u, v)`` [m]."""
        u, v = (float(p) for p in np.asarray(params, dtype=np.float64).reshape(2))
        h, hu, hv, huu, huv, hvv = self.height(u, v)
        e1, e2, n0 = self.frame.T
        g = n0 - hu * e1 - hv * e2  # Eq. (M2), before normalising
        size = math.sqrt(1.0 + hu * hu + hv * hv)
        normal = g / size
        columns = np.empty((3, 6))
        columns[:, 0] = self.origin + u * e1 + v * e2 + h * n0  # Eq. (M1)
        columns[:, 1] = normal
        columns[:, 2] = e1 + hu * n0
        columns[:, 3] = e2 + hv * n0
        for col, gd in ((4, -huu * e1 - huv * e2), (5, -huv * e1 - hvv * e2)):
            columns[:, col] = (gd - normal * (normal @ gd)) / size
        rotation = self.placement[:3, :3]
        moved = rotation @ columns
        moved[:, 0] += self.placement[:3, 3]
        return SurfaceJet.from_columns(moved)

    def placed(self, T: Any) -> MeshPatch:
        """Return the patch moved by placement ``T``."""
        return dataclasses.replace(self, placement=as_placement(T) @ self.placement)


def _frame(normal: FloatArray) -> FloatArray:
    """An orthonormal frame ``(e_1, e_2, n)`` with ``n`` the given unit normal."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    e1 = np.cross(helper, normal)
    e1 /= np.linalg.norm(e1)
    return np.stack([e1, np.cross(normal, e1), normal], axis=1)


def _samples(
    vertices: FloatArray, faces: NDArray[np.int64], normals: FloatArray, areas: FloatArray,
    origin: FloatArray, n0: FloatArray, radius: float, spacing: float,
) -> tuple[FloatArray, FloatArray]:  # fmt: skip
    """Points of the triangles facing ``n0`` near ``origin`` and the area each stands for."""
    corners = vertices[faces]  # (F, 3, 3)
    gap = np.linalg.norm(corners - origin, axis=2).min(axis=1)
    edge = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
    near = (gap <= radius + edge) & (normals @ n0 >= _FACING_COS)
    points, weights = [], []
    for tri, longest, area in zip(corners[near], edge[near], areas[near], strict=True):
        m = int(min(max(math.ceil(longest / spacing), 1), 24))
        # Barycentric grid of level m: the centroids of the m^2 sub-triangles.
        i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        keep = i + j <= m - 1
        up = np.stack([(i + 1 / 3), (j + 1 / 3)], axis=-1)[keep] / m
        down = np.stack([(i + 2 / 3), (j + 2 / 3)], axis=-1)[(i + j <= m - 2)] / m
        bary = np.concatenate([up, down])
        pts = tri[0] + bary[:, :1] * (tri[1] - tri[0]) + bary[:, 1:] * (tri[2] - tri[0])
        points.append(pts)
        weights.append(np.full(len(pts), area / m**2))
    if not points:
        return np.zeros((0, 3)), np.zeros(0)
    P, W = np.concatenate(points), np.concatenate(weights)
    inside = np.linalg.norm(P - origin, axis=1) <= radius
    return P[inside], W[inside]


def _fit(
    P: FloatArray,
    W: FloatArray,
    origin: FloatArray,
    frame: FloatArray,
    a: float,
    degree: int,
    anchored: bool = False,
) -> FloatArray | None:
    """Coefficients of Eq. (M3), or None when the samples do not determine them.

    ``anchored``: the constant and linear terms are zero (the model passes through ``origin``
    with the frame's normal there), the others fitted.
    """
    local = (P - origin) @ frame
    s, t, z = local[:, 0] / a, local[:, 1] / a, local[:, 2]
    exps = _exponents(degree)
    if len(P) < 3 * len(exps):
        return None
    quadrants = {(bool(x > 0), bool(y > 0)) for x, y in zip(s.tolist(), t.tolist(), strict=True)}
    if len(quadrants) < 4:  # the square must be surrounded by samples, not extrapolated
        return None
    w = np.sqrt(W * np.exp(-(s * s + t * t)))
    used = [k for k, (i, j) in enumerate(exps) if not anchored or i + j >= 2]
    A = np.stack([s**i * t**j for i, j in (exps[k] for k in used)], axis=1) * w[:, None]
    fitted, _, rank, _ = np.linalg.lstsq(A, z * w, rcond=None)
    if rank < len(used):
        return None
    coefficients = np.zeros(len(exps))
    coefficients[used] = fitted
    return coefficients


def fit_mesh_patch(
    name: str,
    mesh: Any,
    point: ArrayLike,
    normal: ArrayLike,
    max_half_width_m: float = 0.02,
    min_half_width_m: float = 0.002,
    tolerance_m: float = 3e-4,
    degree: int = DEGREE,
    anchored: bool = False,
) -> MeshPatch:
    """The local model (Eqs. (M1)-(M3)) of ``mesh`` around the contact ``point``.

    Args:
        name: The region's name (the finger's).
        mesh: A ``trimesh.Trimesh`` in the object frame [m], outward normals.
        point: The contact point ``p_0`` on (or within a fraction of a millimetre of) the mesh.
        normal: The outward normal there (it sets the frame; the fit tilts the model as needed).
        max_half_width_m: Largest half width ``a`` tried [m].
        min_half_width_m: Smallest one [m].
        tolerance_m: Largest distance from the model to the mesh accepted over the patch [m].
        degree: Degree of the height polynomial.
        anchored: The model passes through ``point`` with the normal ``normal`` there
            (``h(0, 0) = h_u(0, 0) = h_v(0, 0) = 0``): a grasp whose contact is there, with that
            normal, is on the model as it is (the atlas's first chart is the starting grasp).

    Raises:
        SurfaceModelError: No half width down to ``min_half_width_m`` gives a model within
            ``tolerance_m`` of the mesh (a sharp edge or a corner at the contact, too few
            triangles facing the normal), or the arguments are out of range.
    """
    p0 = np.asarray(point, dtype=np.float64).reshape(3)
    n0 = np.asarray(normal, dtype=np.float64).reshape(3)
    if not (np.isfinite(p0).all() and np.isfinite(n0).all() and np.linalg.norm(n0) > 0):
        raise SurfaceModelError(f"{name}: the contact point and normal must be finite 3-vectors")
    if not 0 < min_half_width_m <= max_half_width_m or not tolerance_m > 0 or degree < 2:
        raise SurfaceModelError(
            f"{name}: need 0 < min_half_width_m <= max_half_width_m, tolerance_m > 0, degree >= 2"
        )
    n0 = n0 / np.linalg.norm(n0)
    frame = _frame(n0)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces)
    face_normals = np.asarray(mesh.face_normals, dtype=np.float64)
    areas = np.asarray(mesh.area_faces, dtype=np.float64)
    a, worst = max_half_width_m, math.inf
    while a >= min_half_width_m * (1 - 1e-9):
        radius = _FIT_RADIUS * a
        P, W = _samples(vertices, faces, face_normals, areas, p0, n0, radius, a / 8)
        coefficients = _fit(P, W, p0, frame, a, degree, anchored)
        if coefficients is None and degree > 2:
            coefficients = _fit(P, W, p0, frame, a, 2, anchored)
            used = 2
        else:
            used = degree
        if coefficients is not None:
            patch = MeshPatch(name, p0, frame, coefficients, a, used, (0.0, 0.0), 0.0, 0.0)
            distance, angle = model_errors(patch, mesh)
            worst = min(worst, distance)
            if distance <= tolerance_m and angle < math.pi / 2:
                return dataclasses.replace(patch, fit_error_m=distance, normal_error_rad=angle)
        a *= _SHRINK
    found = "no fit" if math.isinf(worst) else f"at best {worst * 1e3:.2f} mm off the mesh"
    raise SurfaceModelError(
        f"{name}: no smooth local model of the mesh around the contact at {p0.round(4).tolist()} "
        f"within {tolerance_m * 1e3:g} mm for half widths {min_half_width_m * 1e3:g}.."
        f"{max_half_width_m * 1e3:g} mm ({found}): a sharp edge, a corner or too few triangles "
        "facing the contact normal; choose a contact on a smoother part of the object"
    )


def model_errors(patch: MeshPatch, mesh: Any, grid: int = _CHECK_GRID) -> tuple[float, float]:
    """Largest distance [m] and normal angle [rad] from ``patch`` to ``mesh`` on a grid.

    ``mesh`` is in the patch's object frame (the patch's placement is not applied).
    """
    import trimesh

    a = patch.half_width_m
    axis = np.linspace(-a, a, grid)
    unplaced = dataclasses.replace(patch, placement=np.eye(4))
    jets = [unplaced.evaluate((u, v)) for u in axis for v in axis]
    points = np.array([j.point for j in jets])
    normals = np.array([j.normal for j in jets])
    _, distance, triangle = trimesh.proximity.closest_point(mesh, points)
    cosines = np.clip((np.asarray(mesh.face_normals)[triangle] * normals).sum(axis=1), -1, 1)
    return float(np.max(distance)), float(np.max(np.arccos(cosines)))
