"""Candidate contact sets of 2, 3 and 4 fingers on a mesh, with the cheap tests before the IK.

One draw, from its own seed: a thumb contact uniform over the surface area; a ray into the object
within a cone about the inward thumb normal leaves it at the opposite point ``o``, within the
hand's span. Then, by the number of fingers:

* 2 (thumb + index): the index at ``o``;
* 3 (thumb, index, middle): index and middle at the surface points nearest to ``o +- s/2 d``,
  ``d`` a random tangent at ``o`` and ``s`` a finger spacing;
* 4 (thumb, index, middle, ring): the middle at ``o``, index and ring a spacing away on either
  side (the sampler of ``sahgrasp bench grasps``).

A set is kept when the fingers' normals agree (fan), the fingers are a spacing apart, the thumb
opposes the fingers (its normal within twice the friction angle, ``2 atan(mu)``, of the opposite
of the fingers' mean normal, at least 30 degrees), every contact is exposed (not inside another
shell), its contacts could hold the object -- the test that needs no hand at all: force closure
of the contact set (a set without it never gives a force-closure grasp), or for two fingers the
antipodal condition (the line between the contacts inside both friction cones; two hard-finger
contacts cannot be in force closure, since nothing resists a torque about that line) -- and
every fingertip sphere fits against the surface at its contact. Last, every contact must have
room in front of it: its outward normal must not meet the object again within
:data:`CAVITY_RADII` fingertip radii (a contact on the inside of a tube or a cup, whose finger
would have to enter the cavity along its walls), and its fingertip must be able to leave the
object's convex hull along a straight path clear of the object no longer than as many radii,
in a direction within 85 degrees of its normal (a contact deep down a cup, which the finger
would have to reach over the rim).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sahgrasp.objects.grasp_sampler import (
    HandReach,
    SamplerSettings,
    SurfaceMesh,
    ray_exit,
    spaced_neighbour,
    thumb_opposes,
)
from sahgrasp.objects.reach import derive_reach, finger_set, hand_reach
from sahgrasp.quality.wrench import CONE_EDGES, force_closure, primitive_wrenches

__all__ = [
    "CAVITY_RADII",
    "Candidate",
    "CandidateDraw",
    "NearestPoint",
    "ObjectFrame",
    "derive_reach",
    "finger_set",
    "hand_reach",
]

FloatArray = NDArray[np.float64]
Contact = tuple[FloatArray, FloatArray]

_RAY_EPS_M = 1e-7
"""Ray crossings this near the origin are its own face (as in :meth:`SurfaceMesh.ray_hits`)."""
_OFF_SURFACE_M = 1e-6
CAVITY_RADII = 4.0
"""A contact whose outward normal meets the object again within this many fingertip radii is
in a cavity a finger rarely enters with the object as an obstacle (40 mm for the SAH). On the
objects of ``sahgrasp bench plan`` (the catalog, the shipped and the test meshes), the IK solved
3 of the 37 candidates with such a contact (on the tube, the cups and the mug), at 13 ms of CPU
each against 7 ms for the others, of which 80% were solved: these candidates are rejected
before the IK (``cavity``). The same distance bounds the path a fingertip may take to leave
the object's convex hull (``deep``, :meth:`CandidateDraw._room`): on the same objects, the IK
solved 5 of the 50 candidates whose fingertip has no such path (on the mug and the cups), at
16 ms of CPU each."""
_ESCAPE_TILTS_DEG = (0.0, 30.0, 60.0, 85.0)
"""Tilts from a contact's normal of the directions its fingertip may leave the hull along (8
azimuths each but the first)."""


def _escape_directions() -> FloatArray:
    """The unit escape directions (K, 3) about the z axis (:data:`_ESCAPE_TILTS_DEG`)."""
    out = [(0.0, 0.0, 1.0)]
    for tilt in _ESCAPE_TILTS_DEG[1:]:
        t = math.radians(tilt)
        out += [
            (math.sin(t) * math.cos(a), math.sin(t) * math.sin(a), math.cos(t))
            for a in 2.0 * math.pi * np.arange(8) / 8
        ]
    return np.array(out)


_ESCAPES = _escape_directions()


@dataclass(frozen=True)
class ObjectFrame:
    """What the quality needs of an object: its centroid and its radius about it.

    Attributes:
        centroid_m: Centre of the enclosed volume, world frame [m].
        radius_m: Largest distance from the centroid to the surface [m] (the torque scale).
    """

    centroid_m: FloatArray
    radius_m: float

    @classmethod
    def of(cls, vertices_m: FloatArray, faces: NDArray[np.intp]) -> ObjectFrame:
        """From a closed outward-wound mesh (world frame): volume centroid, radius about it."""
        corners = vertices_m[faces]
        # Tetrahedra from the origin to each face: signed volumes and their centroids.
        volumes = np.einsum("ij,ij->i", corners[:, 0], np.cross(corners[:, 1], corners[:, 2]))
        total = float(volumes.sum())
        centroid = (volumes[:, None] * corners.sum(axis=1)).sum(axis=0) / (4.0 * total)
        radius = float(np.linalg.norm(vertices_m - centroid, axis=1).max())
        return cls(centroid, radius)


@dataclass(frozen=True)
class Candidate:
    """A contact set that passed the tests before the IK.

    Attributes:
        fingers: Finger names, thumb first.
        points_m: Contact points, world frame [m], (k, 3).
        normals: Outward unit normals there, (k, 3).
        seed: The seed of the draw that gave it (:meth:`CandidateDraw.draw` reproduces it).
        force_closure: The contact set is in force closure
            (:func:`sahgrasp.quality.wrench.force_closure`; never for two fingers); the planner
            computes the epsilon of those it verifies.
    """

    fingers: tuple[str, ...]
    points_m: FloatArray
    normals: FloatArray
    seed: int
    force_closure: bool = False


class CandidateDraw:
    """Draws candidate contact sets on one surface (module docstring).

    Args:
        surface: The object's surface, world frame.
        reach: The hand's spacing, span and fingertip radius.
        frame: The object's centroid and radius (for the force-closure test).
        mu: Coulomb friction coefficient of the force-closure test.
        settings: Opposition and fit tolerances.
        edges: Friction cone edges of the force-closure test.
    """

    def __init__(
        self,
        surface: SurfaceMesh,
        reach: HandReach,
        frame: ObjectFrame,
        mu: float,
        settings: SamplerSettings | None = None,
        edges: int = CONE_EDGES,
    ) -> None:
        settings = settings or SamplerSettings()
        self.edges = edges
        self.single_shell = _shells(surface) == 1
        self.surface = surface
        self.nearest = NearestPoint(surface.triangles, surface.normals)
        self.reach = reach
        self.frame = frame
        self.mu = mu
        self.cone_cos = math.cos(math.radians(settings.approach_cone_deg))
        # Friction lets a thumb push up to atan(mu) off the line to the fingers, and the fingers
        # too: opposition within twice the friction angle can still be force closure (a cone's
        # side pinch), which the force-closure test then decides.
        opposition_deg = max(settings.opposition_deg, 2.0 * math.degrees(math.atan(mu)))
        self.opposition_cos = math.cos(math.radians(opposition_deg))
        self.early_cos = math.cos(
            math.radians(min(opposition_deg + 0.5 * settings.finger_fan_deg, 90.0))
        )
        self.fan_cos = math.cos(math.radians(settings.finger_fan_deg))
        self.clearance_m = reach.fingertip_radius_m - settings.surface_tolerance_m
        self.cavity_m = CAVITY_RADII * reach.fingertip_radius_m
        from scipy.spatial import ConvexHull

        # The hull's facets as a x <= b with unit a (Qhull's equations: a x + offset <= 0).
        hull = ConvexHull(surface.triangles.reshape(-1, 3)).equations
        self.hull_normals, self.hull_offsets = hull[:, :3], -hull[:, 3]
        self.friction_cos = math.cos(math.atan(mu))

    def draw(self, fingers: tuple[str, ...], seed: int) -> Candidate | str:
        """One draw for ``fingers`` (thumb first) from ``seed``: a candidate or why not."""
        rng = np.random.default_rng(seed)
        thumb = self.surface.sample_point(rng)
        opposite = self._opposite(rng, thumb)
        if opposite is None:
            return "no_opposite"
        count = len(fingers)
        # Early: the thumb must roughly oppose the opposite point (exactly for two fingers, within
        # the fingers' fan for more) before the costlier search of the neighbouring fingers.
        if float(thumb[1] @ opposite[1]) > -(self.opposition_cos if count == 2 else self.early_cos):
            return "opposition"
        if count == 2:
            contacts = [thumb, opposite]
        else:
            direction = _tangent(rng, opposite[1])
            spacing = float(rng.uniform(*self.reach.finger_spacing_m))
            if count == 3:
                steps = [(1.0, 0.5 * spacing), (-1.0, 0.5 * spacing)]
            else:
                steps = [(1.0, spacing), (-1.0, spacing)]
            neighbours = []
            for sign, step in steps:
                found = self._neighbour(opposite[0], sign * direction, step, count == 3)
                if found is None:
                    return "spacing"
                if found[1] @ opposite[1] < self.fan_cos:
                    return "fan"
                neighbours.append(found)
            if count == 3:
                if neighbours[0][1] @ neighbours[1][1] < self.fan_cos:
                    return "fan"
                contacts = [thumb, neighbours[0], neighbours[1]]
            else:
                contacts = [thumb, neighbours[0], opposite, neighbours[1]]
                if np.linalg.norm(contacts[1][0] - contacts[3][0]) < self.reach.finger_spacing_m[0]:
                    return "spacing"
        for reason, check in (("opposition", self._opposed), ("hidden", self._exposed)):
            if not check(contacts):
                return reason
        points = np.array([p for p, _ in contacts])
        normals = np.array([n for _, n in contacts])
        if count == 2:
            if not self._antipodal(contacts):
                return "no_closure"
            closure = False
        else:
            wrenches = primitive_wrenches(
                points, normals, self.frame.centroid_m, self.frame.radius_m, self.mu, self.edges
            )
            # Force closure without the hull (a hundredth of its time): most sets drawn fail
            # here, and only the verified grasps need their epsilon.
            if not force_closure(wrenches.reshape(-1, 6)):
                return "no_closure"
            closure = True
        # Then the tests of closest points and rays, asked of the few sets that hold: almost
        # every set that reaches the fit test passes it.
        if not self._fits(contacts):
            return "fingertip_fit"
        for point, normal in contacts:
            room = self._room(point, normal)
            if room is not None:
                return room
        return Candidate(fingers, points, normals, seed, closure)

    def _opposite(self, rng: np.random.Generator, thumb: Contact) -> Contact | None:
        point, normal = thumb
        direction = _in_cone(rng, -normal, self.cone_cos)
        hits = self.nearest.ray_hits(point, direction)
        return ray_exit(rng, point, direction, hits, self.surface.normals, self.reach.span_m)

    def _neighbour(
        self, start: FloatArray, direction: FloatArray, step_m: float, half: bool
    ) -> Contact | None:
        """The surface point nearest to ``start + step * direction``, at a chord of ``step_m``.

        ``step`` is stretched while the surface curves away; the chord must be within the
        spacing range (halved for ``half``).
        """
        lo, hi = self.reach.finger_spacing_m
        if half:
            lo, hi = 0.5 * lo, 0.5 * hi
        return spaced_neighbour(
            self.nearest.closest, self.surface.normals, start, direction, step_m, (lo, hi)
        )

    def _opposed(self, contacts: list[Contact]) -> bool:
        return thumb_opposes(contacts, self.opposition_cos)

    def _exposed(self, contacts: list[Contact]) -> bool:
        if self.single_shell:  # one closed shell: no surface point is inside another
            return True
        return all(self.nearest.shells_around(p + _OFF_SURFACE_M * n, n) == 0 for p, n in contacts)

    def _fits(self, contacts: list[Contact]) -> bool:
        radius = self.reach.fingertip_radius_m
        return all(self.nearest.closest(p + radius * n)[2] >= self.clearance_m for p, n in contacts)

    def _room(self, point: FloatArray, normal: FloatArray) -> str | None:
        """Why the contact at ``point`` has no room in front of it (module docstring), or None.

        A fingertip whose centre is outside the convex hull has room: the normal ray leaves the
        hull there and never meets the object again (the fit test has cleared the way to the
        centre). Inside the hull, ``cavity`` if the ray meets the object within the cavity
        distance, ``deep`` if the fingertip cannot leave the hull along one of the escape
        directions about ``normal`` (:data:`_ESCAPE_TILTS_DEG`) within that distance without
        meeting the object first: the hull's exits first (one product for all directions), a
        ray of the mesh only for the short ones, nearest first.
        """
        centre = point + self.reach.fingertip_radius_m * normal
        slack = self.hull_offsets - self.hull_normals @ centre
        if slack.min() <= 0.0:
            return None
        if np.any(
            self.nearest.ray_hits(point + _OFF_SURFACE_M * normal, normal)[0] < self.cavity_m
        ):
            return "cavity"
        u, v = _basis(normal)
        directions = _ESCAPES @ np.array([u, v, normal])
        along = self.hull_normals @ directions.T  # (facets, directions)
        leaving = along > 1e-12
        exits = np.where(leaving, slack[:, None] / np.where(leaving, along, 1.0), np.inf).min(0)
        for k in np.argsort(exits, kind="stable").tolist():
            if exits[k] > self.cavity_m:
                return "deep"
            hits = self.nearest.ray_hits(centre, directions[k])[0]
            if not len(hits) or hits[0] >= exits[k]:
                return None
        return "deep"

    def _antipodal(self, contacts: list[Contact]) -> bool:
        """Two contacts: the line between them inside both friction cones."""
        (p1, n1), (p2, n2) = contacts
        axis = p2 - p1
        length = float(np.linalg.norm(axis))
        if length < 1e-9:
            return False
        axis /= length
        # Each contact pushes along -n: the line must lie within both friction cones.
        return bool(-n1 @ axis >= self.friction_cos and n2 @ axis >= self.friction_cos)


class NearestPoint:
    """Closest points and ray crossings of a triangle mesh, exact, one query at a time.

    The nearest point of the surface's corners and face centroids bounds the distance from
    above; each face's bounding sphere (about its centroid) and its plane bound the face's
    distance from below: only faces whose lower bound is within the upper one can hold the
    closest point (:meth:`SurfaceMesh.closest` with a tighter bound, which this replaces in the
    draws, without trimesh's per-call set-up). Meshes of many faces look the nearest surface
    point up in a k-d tree and the faces near it in an R-tree instead of measuring them all.

    Args:
        triangles: Corners of each face, (M, 3, 3) [m].
        normals: Outward unit normal of each face, (M, 3).
    """

    _TREE_FACES = 256
    """Meshes with more faces than this look the nearest surface point up in a k-d tree and
    the faces whose boxes meet the ball it bounds in an R-tree."""

    def __init__(self, triangles: FloatArray, normals: FloatArray) -> None:
        self.face_normals = normals
        self.a = np.ascontiguousarray(triangles[:, 0])
        self.ab = triangles[:, 1] - triangles[:, 0]
        self.ac = triangles[:, 2] - triangles[:, 0]
        self.centroids = triangles.mean(axis=1)
        self.radii = np.linalg.norm(triangles - self.centroids[:, None], axis=2).max(axis=1)
        self.max_radius = float(self.radii.max())
        self.radii_sq = self.radii**2
        normals = np.cross(self.ab, self.ac)
        self.unit_normals = normals / np.linalg.norm(normals, axis=1)[:, None]
        self.plane_offsets = (self.unit_normals * self.a).sum(axis=1)
        self.samples = np.unique(np.concatenate([triangles.reshape(-1, 3), self.centroids]), axis=0)
        self._corners = triangles.reshape(-1, 9).tolist()
        self.sample_tree: Any = None
        self.box_tree: Any = None
        if len(triangles) > self._TREE_FACES:
            from scipy.spatial import cKDTree

            self.sample_tree = cKDTree(self.samples)
            self.box_tree = _box_tree(triangles)

    def ray_hits(
        self, origin: FloatArray, direction: FloatArray
    ) -> tuple[FloatArray, NDArray[np.intp]]:
        """Distances [m] and faces of a unit ray's crossings (:meth:`SurfaceMesh.ray_hits`).

        Nearest first, the origin's own face left out.
        The cross products are written out: ``np.cross`` costs more in its set-up than in its
        arithmetic on a few faces.
        """
        offset = self.centroids - origin
        along = offset @ direction
        near = (offset * offset).sum(axis=1) - along * along <= self.radii_sq
        faces = np.flatnonzero(near & (along >= -self.radii))
        e1, e2, v0 = self.ab[faces], self.ac[faces], self.a[faces]
        dx, dy, dz = float(direction[0]), float(direction[1]), float(direction[2])
        # p = direction x e2, det = e1 . p (Moller-Trumbore).
        px = dy * e2[:, 2] - dz * e2[:, 1]
        py = dz * e2[:, 0] - dx * e2[:, 2]
        pz = dx * e2[:, 1] - dy * e2[:, 0]
        det = e1[:, 0] * px + e1[:, 1] * py + e1[:, 2] * pz
        ok = np.abs(det) > 1e-18
        inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
        sv = origin - v0
        u = (sv[:, 0] * px + sv[:, 1] * py + sv[:, 2] * pz) * inv
        # q = s x e1.
        qx = sv[:, 1] * e1[:, 2] - sv[:, 2] * e1[:, 1]
        qy = sv[:, 2] * e1[:, 0] - sv[:, 0] * e1[:, 2]
        qz = sv[:, 0] * e1[:, 1] - sv[:, 1] * e1[:, 0]
        v = (qx * dx + qy * dy + qz * dz) * inv
        t = (e2[:, 0] * qx + e2[:, 1] * qy + e2[:, 2] * qz) * inv
        hit = ok & (u >= 0.0) & (v >= 0.0) & (u + v <= 1.0) & (t > _RAY_EPS_M)
        order = np.argsort(t[hit])
        return t[hit][order], faces[hit][order]

    def shells_around(self, point: FloatArray, direction: FloatArray) -> int:
        """Number of closed shells holding ``point``: exits minus entries of a ray from it."""
        _, faces = self.ray_hits(point, direction)
        return int(np.sign(self.face_normals[faces] @ direction).sum())

    def closest(self, point: FloatArray) -> tuple[FloatArray, int, float]:
        """Closest point of the mesh to ``point`` [m], its face, and the distance [m]."""
        if self.sample_tree is None:
            bound = float(np.sqrt(((self.samples - point) ** 2).sum(axis=1).min()))
            near = None
            offset = self.centroids - point
            sphere = np.sqrt((offset * offset).sum(axis=1)) - self.radii
            plane = np.abs(self.plane_offsets - self.unit_normals @ point)
        else:
            bound = float(self.sample_tree.query(point)[0])
            box = (*(point - bound).tolist(), *(point + bound).tolist())
            near = np.fromiter(self.box_tree.intersection(box), dtype=np.intp)
            offset = self.centroids[near] - point
            sphere = np.sqrt((offset * offset).sum(axis=1)) - self.radii[near]
            plane = np.abs(self.plane_offsets[near] - self.unit_normals[near] @ point)
        lower = np.maximum(sphere, plane)
        kept = np.flatnonzero(lower <= bound)
        kept = kept[np.argsort(lower[kept], kind="stable")]
        faces = kept if near is None else near[kept]
        # Faces by increasing lower bound, in plain floats (numpy's per-call overhead costs more
        # on a few faces), until the next bound exceeds the best distance found.
        px, py, pz = float(point[0]), float(point[1]), float(point[2])
        found = (0.0, 0.0, 0.0)
        face, best_sq = -1, math.inf
        for f, low in zip(faces.tolist(), lower[kept].tolist(), strict=True):
            if low > 0.0 and low * low > best_sq:
                break
            q = _closest_on_triangle(px, py, pz, self._corners[f])
            d_sq = (q[0] - px) ** 2 + (q[1] - py) ** 2 + (q[2] - pz) ** 2
            if d_sq < best_sq:
                found, face, best_sq = q, f, d_sq
        return np.array(found), face, math.sqrt(best_sq)


def _box_tree(triangles: FloatArray) -> Any:
    """An R-tree of the triangles' axis-aligned boxes (3-D), item i the face i."""
    from rtree import index

    properties = index.Property()
    properties.dimension = 3
    boxes = np.concatenate([triangles.min(axis=1), triangles.max(axis=1)], axis=1)
    stream = ((i, tuple(b), None) for i, b in enumerate(boxes.tolist()))
    return index.Index(stream, properties=properties)


def _closest_on_triangle(
    px: float, py: float, pz: float, corners: list[float]
) -> tuple[float, float, float]:
    """Closest point to ``p`` on the triangle of ``corners`` (a, b, c flattened) [m].

    The Voronoi regions of the corners, edges and face, tested in turn (C. Ericson, "Real-Time
    Collision Detection", Morgan Kaufmann 2005, section 5.1.5).
    """
    ax, ay, az, bx, by, bz, cx, cy, cz = corners
    abx, aby, abz = bx - ax, by - ay, bz - az
    acx, acy, acz = cx - ax, cy - ay, cz - az
    apx, apy, apz = px - ax, py - ay, pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az
    bpx, bpy, bpz = px - bx, py - by, pz - bz
    d3 = abx * bpx + aby * bpy + abz * bpz
    d4 = acx * bpx + acy * bpy + acz * bpz
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return ax + v * abx, ay + v * aby, az + v * abz
    cpx, cpy, cpz = px - cx, py - cy, pz - cz
    d5 = abx * cpx + aby * cpy + abz * cpz
    d6 = acx * cpx + acy * cpy + acz * cpz
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return ax + w * acx, ay + w * acy, az + w * acz
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + w * (cx - bx), by + w * (cy - by), bz + w * (cz - bz)
    total = va + vb + vc
    v, w = vb / total, vc / total
    return ax + v * abx + w * acx, ay + v * aby + w * acy, az + v * abz + w * acz


def _shells(surface: SurfaceMesh) -> int:
    """Connected components of the surface's triangles (sharing a corner point)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    corners = surface.triangles.reshape(-1, 3)
    _, vertex = np.unique(np.round(corners, 12), axis=0, return_inverse=True)
    vertex = vertex.reshape(-1, 3)
    face = np.repeat(np.arange(len(vertex)), 3)
    n_faces, n_vertices = len(vertex), int(vertex.max()) + 1
    # Faces and vertices as one bipartite graph: a face joins its three corners.
    graph = coo_matrix(
        (np.ones(face.size), (face, n_faces + vertex.ravel())),
        shape=(n_faces + n_vertices, n_faces + n_vertices),
    )
    return int(connected_components(graph, directed=False)[0])


def _basis(axis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Two unit vectors orthogonal to the unit ``axis`` and to each other.

    Plain floats: a draw makes many, and ``np.cross`` on three numbers costs more than the
    arithmetic.
    """
    x, y, z = float(axis[0]), float(axis[1]), float(axis[2])
    # u = axis x helper, helper e_x (or e_y when the axis is near x).
    u = (0.0, z, -y) if abs(x) < 0.9 else (-z, 0.0, x)
    scale = 1.0 / math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
    ux, uy, uz = u[0] * scale, u[1] * scale, u[2] * scale
    v = (y * uz - z * uy, z * ux - x * uz, x * uy - y * ux)
    return np.array((ux, uy, uz)), np.array(v)


def _tangent(rng: np.random.Generator, normal: FloatArray) -> FloatArray:
    u, v = _basis(normal)
    angle = rng.uniform(0.0, 2.0 * math.pi)
    return math.cos(angle) * u + math.sin(angle) * v


def _in_cone(rng: np.random.Generator, axis: FloatArray, cos_half_angle: float) -> FloatArray:
    cos_t = rng.uniform(cos_half_angle, 1.0)
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    return cos_t * axis + sin_t * _tangent(rng, axis)
