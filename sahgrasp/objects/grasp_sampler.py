"""Four-finger contact sets sampled on a triangle mesh the way a grasp planner samples them.

An antipodal sampler: a thumb contact drawn uniformly over the surface area; a ray from it into the
object, within a cone about the inward thumb normal, leaves the object where the middle finger
goes; the index and ring contacts are the surface points closest to two points a finger spacing
away from the middle contact along a random tangent direction. A set is kept when the thumb opposes
the fingers, the spacings and the thumb-to-middle span are within the hand's reach, and every
fingertip sphere fits against the surface at its contact without entering the object elsewhere.

Targets carry the surface's OUTWARD unit normal (the fingertip pushes inwards, along ``-normal``).
The mesh must be closed, its faces counter-clockwise seen from outside (a mesh wound the other way
is detected by its negative volume and flipped); overlapping closed shells (an object assembled
from solids) are fine: a point of one shell inside another is not offered as a contact.
"""

from __future__ import annotations

import math
import warnings
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh.triangles
from numpy.typing import ArrayLike, NDArray

from sahgrasp.core.errors import HandModelError, SahGraspError
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hands import DEFAULT_HAND, HANDS
from sahgrasp.objects.body import GraspObject

__all__ = [
    "FINGERS",
    "GraspSamplingError",
    "HandReach",
    "SamplerSettings",
    "SurfaceMesh",
    "as_surface",
    "ray_exit",
    "registered_reach",
    "sample_contact_sets",
    "sample_object_grasps",
    "spaced_neighbour",
    "thumb_opposes",
]

FloatArray = NDArray[np.float64]

FINGERS = ("thumb", "index", "middle", "ring")
"""Fingers of a sampled contact set, in the order of the returned contacts."""

_RAY_EPS_M = 1e-7
"""Hits closer than this to a ray's origin are the origin's own face [m]."""
_SPACING_ITERATIONS = 4
"""Projections allowed to bring a finger's chord to the drawn spacing."""
_OFF_SURFACE_M = 1e-6
"""Offset along the normal of the point whose winding number tells if a contact is exposed [m]."""


class GraspSamplingError(SahGraspError):
    """A mesh cannot be sampled (empty, malformed, open) or yields too few contact sets."""


@dataclass(frozen=True)
class HandReach:
    """What a hand can span, for the sampler.

    Attributes:
        finger_spacing_m: Range of the distance between the middle contact and the index (or
            ring) contact [m].
        span_m: Range of the thumb-to-middle contact distance [m].
        fingertip_radius_m: Radius of the fingertip spheres [m].
    """

    finger_spacing_m: tuple[float, float]
    span_m: tuple[float, float]
    fingertip_radius_m: float

    def __post_init__(self) -> None:
        for name in ("finger_spacing_m", "span_m"):
            lo, hi = getattr(self, name)
            if not 0.0 < lo < hi:
                raise GraspSamplingError(f"{name} must be (lower, upper) with 0 < lower < upper")
        if not self.fingertip_radius_m > 0.0:
            raise GraspSamplingError("fingertip_radius_m must be > 0")


def registered_reach(name: str | None = None) -> HandReach:
    """The measured reach of the registered hand ``name`` (default: the default hand).

    The reach is the hand registry's (:class:`sahgrasp.model.hands.SamplerReach`); the default
    hand's was measured with ``solve_ik`` on flat antipodal grasps (docs/results.md, "The SAH's
    reach").

    Raises:
        HandModelError: ``name`` is not registered or its entry gives no reach.
    """
    name = DEFAULT_HAND if name is None else name
    entry = HANDS.lookup(name)
    if entry.reach is None:
        raise HandModelError(
            f"hand {name!r} has no measured reach; sahgrasp.objects.reach.sampler_reach(hand) "
            "derives one from its model"
        )
    r = entry.reach
    return HandReach(r.finger_spacing_m, r.span_m, r.fingertip_radius_m)


def __getattr__(name: str) -> Any:
    # SAH_REACH, the default hand's measured reach, kept for one release.
    if name == "SAH_REACH":
        warnings.warn(
            "sahgrasp.objects.grasp_sampler.SAH_REACH is deprecated; use registered_reach() "
            "(the default hand's) or sahgrasp.objects.reach.sampler_reach(hand)",
            DeprecationWarning,
            stacklevel=2,
        )
        return registered_reach()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


@dataclass(frozen=True)
class SamplerSettings:
    """How strictly a contact set must look like a precision grasp.

    Attributes:
        approach_cone_deg: Half-angle of the cone about the inward thumb normal in which the ray
            to the middle contact is drawn [deg].
        opposition_deg: Largest angle between the thumb normal and the opposite of the fingers'
            mean normal [deg].
        finger_fan_deg: Largest angle between the index (or ring) normal and the middle's [deg].
        surface_tolerance_m: How far a fingertip sphere resting on its contact may dip into the
            mesh elsewhere (chords of a tessellated concave surface) [m].
        max_attempts_per_set: Draws allowed per requested set before giving up.
    """

    approach_cone_deg: float = 20.0
    opposition_deg: float = 30.0
    finger_fan_deg: float = 60.0
    surface_tolerance_m: float = 2e-4
    max_attempts_per_set: int = 500

    def __post_init__(self) -> None:
        for name in ("approach_cone_deg", "opposition_deg", "finger_fan_deg"):
            if not 0.0 < getattr(self, name) <= 90.0:
                raise GraspSamplingError(f"{name} must be in (0, 90] degrees")
        if not self.surface_tolerance_m >= 0.0:
            raise GraspSamplingError("surface_tolerance_m must be >= 0")
        if int(self.max_attempts_per_set) < 1:
            raise GraspSamplingError("max_attempts_per_set must be >= 1")


class SurfaceMesh:
    """A closed triangle mesh with outward unit face normals and the queries the sampler needs.

    Args:
        vertices_m: Vertex positions [m], shape (N, 3).
        faces: Vertex indices of each triangle, shape (M, 3). Zero-area triangles are dropped.

    Raises:
        GraspSamplingError: Wrong shapes, NaN/inf, indices out of range, no triangle of non-zero
            area, or zero enclosed volume (not a closed surface).
    """

    def __init__(self, vertices_m: ArrayLike, faces: ArrayLike) -> None:
        vertices, index = _checked_arrays(vertices_m, faces)
        corners = vertices[index]
        area_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        doubled_areas = np.linalg.norm(area_normals, axis=1)
        keep = doubled_areas > 1e-12 * max(float(np.ptp(vertices, axis=0).max()) ** 2, 1e-300)
        if not keep.any():
            raise GraspSamplingError("the mesh has no triangle of non-zero area")
        corners, area_normals, doubled_areas = (
            corners[keep],
            area_normals[keep],
            doubled_areas[keep],
        )
        # Divergence theorem: 6 V = sum over faces of (corner . area normal).
        volume = float(np.einsum("ij,ij->", corners[:, 0], area_normals)) / 6.0
        if abs(volume) < 1e-12:
            raise GraspSamplingError("the mesh encloses no volume: give a closed surface")
        orientation = 1.0 if volume > 0.0 else -1.0
        self.triangles = corners if volume > 0.0 else corners[:, ::-1]
        self.normals = orientation * area_normals / doubled_areas[:, None]
        self._cumulative_area = np.cumsum(doubled_areas)
        self._centroids = self.triangles.mean(axis=1)
        self._radii = np.linalg.norm(self.triangles - self._centroids[:, None], axis=2).max(axis=1)
        self._radii_sq = self._radii**2
        self._edges = (
            self.triangles[:, 1] - self.triangles[:, 0],
            self.triangles[:, 2] - self.triangles[:, 0],
        )

    def __len__(self) -> int:
        return len(self.triangles)

    def sample_point(self, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
        """Return a point drawn uniformly over the area [m] and its outward unit normal."""
        face = int(
            np.searchsorted(self._cumulative_area, rng.uniform(0.0, self._cumulative_area[-1]))
        )
        face = min(face, len(self.triangles) - 1)
        a, b = rng.uniform(size=2)
        if a + b > 1.0:  # fold the parallelogram back onto the triangle
            a, b = 1.0 - a, 1.0 - b
        e1, e2 = self._edges
        point = self.triangles[face, 0] + a * e1[face] + b * e2[face]
        return point, self.normals[face]

    def ray_hits(
        self, origin: FloatArray, direction: FloatArray
    ) -> tuple[FloatArray, NDArray[np.intp]]:
        """Distances along a unit ray [m] and face indices of its crossings, nearest first.

        Hits within ``_RAY_EPS_M`` of the origin (the origin's own face) are left out.
        """
        # Only faces whose bounding sphere meets the ray can be crossed (Moller-Trumbore on them).
        offset = self._centroids - origin
        along = offset @ direction
        near = (offset * offset).sum(axis=1) - along * along <= self._radii_sq
        faces = np.flatnonzero(near & (along >= -self._radii))
        e1, e2, v0 = self._edges[0][faces], self._edges[1][faces], self.triangles[faces, 0]
        p = np.cross(direction, e2)
        det = (e1 * p).sum(axis=1)
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        s = origin - v0
        u = (s * p).sum(axis=1) * inv
        qv = np.cross(s, e1)
        v = (qv @ direction) * inv
        t = (e2 * qv).sum(axis=1) * inv
        hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > _RAY_EPS_M)
        order = np.argsort(t[hit])
        return t[hit][order], faces[hit][order]

    def shells_around(self, point: FloatArray, direction: FloatArray) -> int:
        """Number of closed shells holding ``point``: exits minus entries of a ray from it."""
        _, faces = self.ray_hits(point, direction)
        return int(np.sign(self.normals[faces] @ direction).sum())

    def closest(self, point: FloatArray) -> tuple[FloatArray, int, float]:
        """Closest point of the mesh to ``point`` [m], its face, and the distance [m]."""
        # The nearest centroid bounds the distance from above and each face's bounding sphere
        # from below: only faces whose sphere is nearer than that bound can hold the closest point.
        to_centroid = np.sqrt(((self._centroids - point) ** 2).sum(axis=1))
        candidates = np.flatnonzero(to_centroid - self._radii <= to_centroid.min())
        closest = trimesh.triangles.closest_point(
            self.triangles[candidates], np.tile(point, (len(candidates), 1))
        )
        distances = np.linalg.norm(closest - point, axis=1)
        best = int(np.argmin(distances))
        return closest[best], int(candidates[best]), float(distances[best])


def _checked_arrays(vertices_m: ArrayLike, faces: ArrayLike) -> tuple[FloatArray, NDArray[np.intp]]:
    try:
        vertices = np.asarray(vertices_m, dtype=np.float64)
        index = np.asarray(faces)
    except (TypeError, ValueError) as exc:
        raise GraspSamplingError(f"mesh vertices and faces must be numeric arrays: {exc}") from exc
    if vertices.ndim != 2 or vertices.shape[1] != 3 or len(vertices) < 4:
        raise GraspSamplingError(f"mesh vertices must have shape (N >= 4, 3), got {vertices.shape}")
    if not np.all(np.isfinite(vertices)):
        raise GraspSamplingError("mesh vertices hold NaN or inf; all must be finite")
    if index.ndim != 2 or index.shape[1] != 3 or len(index) < 4:
        raise GraspSamplingError(f"mesh faces must have shape (M >= 4, 3), got {index.shape}")
    if (
        not np.issubdtype(index.dtype, np.integer)
        or index.min() < 0
        or index.max() >= len(vertices)
    ):
        raise GraspSamplingError(
            f"mesh faces must be integer vertex indices in [0, {len(vertices)})"
        )
    return vertices, index.astype(np.intp)


def as_surface(mesh: Any) -> SurfaceMesh:
    """Return ``mesh`` as a :class:`SurfaceMesh`.

    Args:
        mesh: A :class:`SurfaceMesh`, a ``trimesh.Trimesh`` (or anything with ``vertices`` and
            ``faces``), a :class:`sahgrasp.objects.Mesh`, or a ``(vertices, faces)`` pair.

    Raises:
        GraspSamplingError: Any other input, or a malformed mesh.
    """
    if isinstance(mesh, SurfaceMesh):
        return mesh
    if hasattr(mesh, "vertices_m") and hasattr(mesh, "faces"):
        return SurfaceMesh(mesh.vertices_m, mesh.faces)
    if hasattr(mesh, "vertices") and hasattr(mesh, "faces"):
        return SurfaceMesh(mesh.vertices, mesh.faces)
    if isinstance(mesh, tuple) and len(mesh) == 2:
        return SurfaceMesh(*mesh)
    raise GraspSamplingError(
        f"cannot sample a {type(mesh).__name__}: give a trimesh.Trimesh, a sahgrasp Mesh or a "
        "(vertices, faces) pair"
    )


def sample_contact_sets(
    mesh: Any,
    count: int,
    seed: int,
    reach: HandReach | None = None,
    settings: SamplerSettings | None = None,
    name: str = "grasp",
    on_set: Callable[[], object] | None = None,
) -> list[GraspTarget]:
    """Draw ``count`` four-finger contact sets on ``mesh`` (see the module docstring).

    The same arguments give the same sets, and the first ``k`` sets of a larger ``count`` are the
    sets of ``count = k``.

    Args:
        mesh: The surface, in the world frame (anything :func:`as_surface` accepts).
        count: Number of contact sets.
        seed: Seed of the ``numpy`` generator that draws everything.
        reach: The hand's spacing, span and fingertip radius (default: the default hand's,
            :func:`registered_reach`).
        settings: Opposition and fit tolerances; defaults if None.
        name: Problem names are ``f"{name}-{i}"``.
        on_set: Called after each set is found (progress reporting).

    Raises:
        GraspSamplingError: A malformed mesh, ``count < 0``, or fewer than ``count`` sets found
            in ``count * settings.max_attempts_per_set`` draws (the message counts the reasons
            draws were rejected).
    """
    if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 0:
        raise GraspSamplingError(f"count must be an integer >= 0, got {count!r}")
    surface = as_surface(mesh)
    settings = settings or SamplerSettings()
    reach = registered_reach() if reach is None else reach
    rng = np.random.default_rng(seed)
    draw = _ContactSetDraw(surface, reach, settings)
    sets: list[GraspTarget] = []
    rejected: Counter[str] = Counter()
    for _ in range(count * settings.max_attempts_per_set):
        if len(sets) == count:
            break
        outcome = draw(rng)
        if isinstance(outcome, str):
            rejected[outcome] += 1
            continue
        contacts = (ContactTarget(f, p, n) for f, (p, n) in zip(FINGERS, outcome, strict=True))
        sets.append(GraspTarget(f"{name}-{len(sets)}", contacts))
        if on_set is not None:
            on_set()
    if len(sets) < count:
        raise GraspSamplingError(
            f"{name}: found {len(sets)} of {count} contact sets in "
            f"{count * settings.max_attempts_per_set} draws; rejections: {dict(rejected)}. "
            "Is the object within the hand's reach (span, spacing)?"
        )
    return sets


def sample_object_grasps(
    obj: GraspObject,
    count: int,
    seed: int,
    reach: HandReach | None = None,
    settings: SamplerSettings | None = None,
    on_set: Callable[[], object] | None = None,
) -> list[GraspTarget]:
    """Draw ``count`` contact sets on an object's display mesh, placed in the world.

    Arguments as :func:`sample_contact_sets`. The catalog's display meshes are within 0.05 mm of
    the exact surfaces; the contacts lie on the mesh.
    """
    surface = SurfaceMesh(*_world_mesh(obj))
    return sample_contact_sets(surface, count, seed, reach, settings, obj.name, on_set)


def _world_mesh(obj: GraspObject) -> tuple[FloatArray, NDArray[np.int64]]:
    mesh = obj.mesh().transformed(obj.T_world_object)
    return mesh.vertices_m, mesh.faces


Contact = tuple[FloatArray, FloatArray]


class _ContactSetDraw:
    """One draw of a contact set: the four contacts, or the reason the draw was rejected."""

    def __init__(self, surface: SurfaceMesh, reach: HandReach, settings: SamplerSettings) -> None:
        self.surface = surface
        self.reach = reach
        self.cone_cos = math.cos(math.radians(settings.approach_cone_deg))
        self.opposition_cos = math.cos(math.radians(settings.opposition_deg))
        self.fan_cos = math.cos(math.radians(settings.finger_fan_deg))
        self.clearance_m = reach.fingertip_radius_m - settings.surface_tolerance_m
        self.checks: tuple[tuple[str, Callable[[list[Contact]], bool]], ...] = (
            ("spacing", self._apart),
            ("opposition", self._opposed),
            ("hidden", self._exposed),
            ("fingertip_fit", self._fits),
        )

    def __call__(self, rng: np.random.Generator) -> list[Contact] | str:
        thumb = self.surface.sample_point(rng)
        middle = self._opposite(rng, thumb)
        if middle is None:
            return "no_opposite"
        direction = _tangent(rng, middle[1])
        spacing = rng.uniform(*self.reach.finger_spacing_m, size=2)
        neighbours = []
        for sign, spacing_m in zip((1.0, -1.0), spacing, strict=True):
            finger = self._neighbour(middle[0], sign * direction, spacing_m)
            if finger is None:
                return "spacing"
            if finger[1] @ middle[1] < self.fan_cos:
                return "fan"
            neighbours.append(finger)
        contacts = [thumb, neighbours[0], middle, neighbours[1]]
        for reason, check in self.checks:
            if not check(contacts):
                return reason
        return contacts

    def _opposite(self, rng: np.random.Generator, thumb: Contact) -> Contact | None:
        """Where a ray into the object from the thumb leaves it within the span, at random."""
        point, normal = thumb
        direction = _in_cone(rng, -normal, self.cone_cos)
        hits = self.surface.ray_hits(point, direction)
        return ray_exit(rng, point, direction, hits, self.surface.normals, self.reach.span_m)

    def _neighbour(
        self, start: FloatArray, direction: FloatArray, spacing_m: float
    ) -> Contact | None:
        """A surface point within the spacing range of ``start``, about ``spacing_m`` away."""
        return spaced_neighbour(
            self.surface.closest, self.surface.normals, start, direction, spacing_m,
            self.reach.finger_spacing_m,
        )  # fmt: skip

    def _apart(self, contacts: list[Contact]) -> bool:
        """Index and ring no closer than the smallest spacing (not folded onto one side)."""
        return bool(
            np.linalg.norm(contacts[1][0] - contacts[3][0]) >= self.reach.finger_spacing_m[0]
        )

    def _opposed(self, contacts: list[Contact]) -> bool:
        return thumb_opposes(contacts, self.opposition_cos)

    def _exposed(self, contacts: list[Contact]) -> bool:
        """No contact lies inside another shell of the object (parts of assembled solids)."""
        return all(self.surface.shells_around(p + _OFF_SURFACE_M * n, n) == 0 for p, n in contacts)

    def _fits(self, contacts: list[Contact]) -> bool:
        """Each fingertip sphere, resting on its contact, stays out of the object."""
        radius = self.reach.fingertip_radius_m
        return all(self.surface.closest(p + radius * n)[2] >= self.clearance_m for p, n in contacts)


def ray_exit(
    rng: np.random.Generator,
    point_m: FloatArray,
    direction: FloatArray,
    hits: tuple[FloatArray, NDArray[np.intp]],
    face_normals: FloatArray,
    span_m: tuple[float, float],
) -> Contact | None:
    """Where a ray from ``point_m`` into the object leaves it within ``span_m``, one at random.

    Args:
        rng: Picks among the exits.
        point_m: The ray's origin on the surface [m].
        direction: The ray's unit direction, into the object.
        hits: The ray's crossings: distances [m] and faces, as ``SurfaceMesh.ray_hits`` gives.
        face_normals: Outward unit normals of the mesh's faces.
        span_m: Range of the distance from the origin to the exit [m].

    Returns:
        The exit point and its face's outward normal; None when no crossing leaving the object
        (the face turned along the ray) is within the span.
    """
    distances, faces = hits
    lo, hi = span_m
    exits = (face_normals[faces] @ direction > 0.0) & (distances >= lo)
    exits &= distances <= hi
    if not exits.any():
        return None
    k = int(rng.choice(np.flatnonzero(exits)))
    return point_m + distances[k] * direction, face_normals[faces[k]]


def spaced_neighbour(
    closest: Callable[[FloatArray], tuple[FloatArray, int, float]],
    face_normals: FloatArray,
    start_m: FloatArray,
    direction: FloatArray,
    step_m: float,
    chord_m: tuple[float, float],
) -> Contact | None:
    """A surface point whose chord from ``start_m`` is in ``chord_m``, about ``step_m`` away.

    The point closest to ``start_m + step * direction``, ``step`` stretched while the surface
    curves away from the tangent line.

    Args:
        closest: The closest surface point to a point: (point, face, distance), as
            ``SurfaceMesh.closest`` gives.
        face_normals: Outward unit normals of the mesh's faces.
        start_m: Where the chord starts, on the surface [m].
        direction: Unit tangent direction to step along.
        step_m: The first step [m].
        chord_m: Range of the chord's length [m].

    Returns:
        The point and its face's outward normal; None when no point in range is found.
    """
    lo, hi = chord_m
    step = step_m
    for _ in range(_SPACING_ITERATIONS):
        point, face, _ = closest(start_m + step * direction)
        chord = float(np.linalg.norm(point - start_m))
        if lo <= chord <= hi:
            return point, face_normals[face]
        if chord < 1e-9:
            return None
        step *= step_m / chord
    return None


def thumb_opposes(contacts: list[Contact], opposition_cos: float) -> bool:
    """Whether the first contact's normal opposes the other contacts' mean normal.

    Within the angle whose cosine is ``opposition_cos``: ``n_0 . m <= -opposition_cos |m|``.
    """
    mean = np.sum([n for _, n in contacts[1:]], axis=0)
    return bool(contacts[0][1] @ mean <= -opposition_cos * np.linalg.norm(mean))


def _basis(axis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors orthogonal to the unit ``axis`` and to each other."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(axis, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(axis, u)


def _tangent(rng: np.random.Generator, normal: FloatArray) -> FloatArray:
    """A unit vector orthogonal to ``normal``, uniform in angle."""
    u, v = _basis(normal)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return math.cos(angle) * u + math.sin(angle) * v


def _in_cone(rng: np.random.Generator, axis: FloatArray, cos_half_angle: float) -> FloatArray:
    """A unit vector uniform over the spherical cap about the unit ``axis``."""
    cos_t = rng.uniform(cos_half_angle, 1.0)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    return cos_t * axis + sin_t * _tangent(rng, axis)
