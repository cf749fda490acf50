"""An independent check of a planned grasp: the plain URDF, the true mesh, the grasp's JSON values.

Nothing of the planner is reused but the hand description's file names: the hand is built again
from its URDF with Pinocchio (a free-flyer wrist, every URDF joint its own coordinate, no virtual
contact joints) and coal (the URDF's collision shapes); the object is the triangle mesh itself (a
``coal.BVHModel``: distances by GJK on its triangles; inside tests per closed shell by trimesh's
ray test), not the convex pieces the IK avoids. The grasp is set
from the values a results file holds (wrist ``xyz``/``quat``, every joint by name) and must pass:

1. every joint within its URDF limits (to 1e-9 rad), every mimic joint equal to
   ``multiplier * leader + offset`` (to 1e-6);
2. every contact: the point on the mesh surface (within :data:`SURFACE_TOLERANCE_M`), the contact
   finger's fingertip sphere centred within ``d_min`` of ``point + R normal``, and that sphere no
   deeper than ``d_min`` in the object;
3. every other link no deeper in the object than ``tolerance_m`` (0.5 mm): a link whose shape
   crosses the mesh is measured by points spread over its surface (at most 1 mm apart), their
   depth below the surface, and by the mesh vertices inside the shape, their depth below its
   faces; a link that crosses no triangle is inside the object only if one of its points is
   (inside one of the mesh's shells, ``Trimesh.contains``);
4. no two links in collision, over the pairs the URDF does not join (links of one joint or of a
   parent and child joint, and the description's excluded pairs, touch by design).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.model.hand import HandDescription
from sahgrasp.objects.grasp_sampler import SurfaceMesh

__all__ = [
    "LINK_TOLERANCE_M",
    "SURFACE_TOLERANCE_M",
    "GraspVerifier",
    "Verdict",
]

FloatArray = NDArray[np.float64]

LINK_TOLERANCE_M = 5e-4
"""Deepest a link other than a contact fingertip may be inside the object [m]."""
SURFACE_TOLERANCE_M = 1e-5
"""Largest distance of a contact point from the mesh surface [m]."""
_SAMPLE_SPACING_M = 1e-3
"""Largest spacing of the points spread over a link's collision shape [m]."""
_POINT_RADIUS_M = 1e-9
"""A contact point is queried as a ball this small (coal measures shapes, not points)."""
_LIMIT_TOL = 1e-9
_MIMIC_TOL = 1e-6


@dataclass(frozen=True)
class Verdict:
    """The outcome of :meth:`GraspVerifier.check`.

    Attributes:
        ok: Every check passed.
        problems: What failed, in words (empty when ``ok``).
        max_link_depth_m: Deepest non-contact link in the object [m] (0 if none enters).
        clearance_m: Smallest signed distance from a non-contact link to the mesh [m].
        closest_link: The link at ``clearance_m``.
        contact_errors_m: Per contact, the fingertip centre's distance from its target [m].
    """

    ok: bool
    problems: tuple[str, ...]
    max_link_depth_m: float
    clearance_m: float
    closest_link: str
    contact_errors_m: tuple[float, ...]


class GraspVerifier:
    """Checks grasps of one hand on one mesh (module docstring).

    Args:
        description: The hand's description (its URDF, fingertip radius, excluded pairs).
        vertices_m: The object's mesh vertices in the world frame [m], (N, 3).
        faces: Its triangles, (M, 3).
        d_min_m: Contact tolerance [m].
        tolerance_m: Deepest a non-contact link may enter the object [m].
    """

    def __init__(
        self,
        description: HandDescription,
        vertices_m: FloatArray,
        faces: NDArray[np.intp],
        d_min_m: float = 1.5e-3,
        tolerance_m: float = LINK_TOLERANCE_M,
    ) -> None:
        urdf = str(description.urdf_path)
        dirs = [str(p) for p in (*description.package_dirs, description.urdf_path.parent)]
        self.model = pin.buildModelFromUrdf(urdf, pin.JointModelFreeFlyer())
        self.geometry = pin.buildGeomFromUrdf(
            self.model, urdf, pin.GeometryType.COLLISION, None, dirs
        )
        self.data = self.model.createData()
        self.geometry_data = pin.GeometryData(self.geometry)
        self.radius_m = description.fingertip_radius_m
        self.d_min_m = d_min_m
        self.tolerance_m = tolerance_m
        self.tips = {f.name: self.model.getFrameId(f.tip_link) for f in description.fingers}
        self.tip_links = {f.name: f.tip_link for f in description.fingers}
        self.mimic = _mimic_joints(urdf)
        objects = self.geometry.geometryObjects
        self.links = [str(self.model.frames[g.parentFrame].name) for g in objects]
        self.pairs = _checked_pairs(self.model, objects, self.links, description)
        self.samples = [_surface_samples(g.geometry) for g in objects]
        self.pair_array = np.array(self.pairs, dtype=np.intp).reshape(-1, 2)
        for g in objects:
            g.geometry.computeLocalAABB()
        self.link_radii = np.array([g.geometry.aabb_radius for g in objects])
        self.link_centres = [np.asarray(g.geometry.aabb_center) for g in objects]
        self.vertices = np.asarray(vertices_m, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.intp)
        self.surface = SurfaceMesh(self.vertices, self.faces)
        self.bvh = coal.BVHModelOBBRSS()
        self.bvh.beginModel(len(self.faces), len(self.vertices))
        self.bvh.addVertices(self.vertices)
        self.bvh.addTriangles(self.faces)
        self.bvh.endModel()
        self.identity = coal.Transform3s()
        self.point_shape = coal.Sphere(_POINT_RADIUS_M)
        self.low, self.high = self.vertices.min(axis=0), self.vertices.max(axis=0)
        import trimesh

        self.trimesh = trimesh.Trimesh(
            self.surface.triangles.reshape(-1, 3),
            np.arange(3 * len(self.surface)).reshape(-1, 3),
            process=True,
        )
        # A point is inside the object when it is inside one of its closed shells: ray parity
        # on all triangles at once would call a point inside two overlapping shells outside.
        self.shells = self.trimesh.split(only_watertight=False) or [self.trimesh]

    def configuration(self, wrist: dict[str, Any], joints: dict[str, float]) -> FloatArray:
        """The plain model's ``q`` from a grasp's wrist ``xyz``/``quat`` and joints by name.

        Raises:
            KeyError: A URDF joint missing from ``joints``.
        """
        q = pin.neutral(self.model)
        q[:3] = wrist["xyz"]
        quat = np.asarray(wrist["quat"], dtype=np.float64)
        q[3:7] = quat / np.linalg.norm(quat)
        for j in range(2, self.model.njoints):
            q[self.model.joints[j].idx_q] = joints[self.model.names[j]]
        return q

    def check(
        self, wrist: dict[str, Any], joints: dict[str, float], contacts: list[dict[str, Any]]
    ) -> Verdict:
        """Check one grasp given as a results file holds it (module docstring).

        Args:
            wrist: ``{"xyz": [...], "quat": [x, y, z, w]}``, world frame.
            joints: Every URDF joint's value by name [rad].
            contacts: ``[{"finger", "point", "normal"}]``, world frame.
        """
        problems: list[str] = []
        missing = [n for n in self.model.names[2:] if n not in joints]
        if missing:
            return Verdict(False, (f"joints missing: {missing}",), math.inf, -math.inf, "", ())
        q = self.configuration(wrist, joints)
        problems += self._limits(q, joints)
        pin.forwardKinematics(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        pin.updateGeometryPlacements(self.model, self.data, self.geometry, self.geometry_data)
        errors, touching = [], set()
        for c in contacts:
            error, problem = self._contact(c)
            errors.append(error)
            if problem:
                problems.append(problem)
            touching.add(self.tip_links.get(c["finger"], ""))
        # Each link shape's box centre in the world: the bounding-sphere tests of both checks.
        centres = np.array(
            [oMg.act(c) for oMg, c in zip(self.geometry_data.oMg, self.link_centres, strict=True)]
        )
        depth, clearance, closest, link_problems = self._links(touching, centres)
        problems += link_problems
        problems += self._self_collisions(centres)
        return Verdict(not problems, tuple(problems), depth, clearance, closest, tuple(errors))

    def _limits(self, q: FloatArray, joints: dict[str, float]) -> list[str]:
        out = []
        lower, upper = self.model.lowerPositionLimit, self.model.upperPositionLimit
        for j in range(2, self.model.njoints):
            i = self.model.joints[j].idx_q
            if not lower[i] - _LIMIT_TOL <= q[i] <= upper[i] + _LIMIT_TOL:
                out.append(
                    f"joint {self.model.names[j]} = {q[i]:.6g} outside "
                    f"[{lower[i]:.6g}, {upper[i]:.6g}]"
                )
        for name, (leader, multiplier, offset) in self.mimic.items():
            expected = multiplier * joints[leader] + offset
            if abs(joints[name] - expected) > _MIMIC_TOL:
                out.append(f"mimic joint {name} = {joints[name]:.6g}, not {expected:.6g}")
        return out

    def _contact(self, contact: dict[str, Any]) -> tuple[float, str]:
        finger = contact["finger"]
        if finger not in self.tips:
            return math.inf, f"contact of unknown finger {finger!r}"
        point = np.asarray(contact["point"], dtype=np.float64)
        normal = np.asarray(contact["normal"], dtype=np.float64)
        centre = np.array(self.data.oMf[self.tips[finger]].translation)
        error = float(np.linalg.norm(centre - (point + self.radius_m * normal)))
        if error > self.d_min_m:
            return error, f"{finger} fingertip {1e3 * error:.3f} mm from its target (d_min)"
        off = self._point_distance(point)
        if off > SURFACE_TOLERANCE_M:
            return error, f"{finger} contact point {1e3 * off:.4f} mm off the mesh surface"
        gap = self._point_distance(centre)
        depth = self.radius_m + gap if self._inside(centre) else self.radius_m - gap
        if depth > self.d_min_m:
            return error, f"{finger} fingertip {1e3 * depth:.3f} mm inside the object (d_min)"
        return error, ""

    def _point_distance(self, point: FloatArray) -> float:
        """Distance [m] from a point to the mesh's triangles, by coal's GJK.

        trimesh's closest point is off by up to 0.1 mm on the thinnest triangles of the
        catalog's meshes; GJK is not.
        """
        placed = coal.Transform3s(np.eye(3), np.asarray(point, dtype=np.float64))
        return _POINT_RADIUS_M + float(
            coal.distance(self.point_shape, placed, self.bvh, self.identity,
                          coal.DistanceRequest(), coal.DistanceResult())
        )  # fmt: skip

    def _signed_distance(self, points: FloatArray) -> FloatArray:
        """Signed distances of points to the mesh [m]: positive outside, negative inside.

        The magnitude is the distance to the nearest triangle; inside, that may be a triangle of
        another shell within the object (the depth is then underestimated by at most that
        shell's overlap).
        """
        import trimesh

        points = np.atleast_2d(np.asarray(points, dtype=np.float64))
        distance = np.asarray(trimesh.proximity.closest_point(self.trimesh, points)[1])
        return np.where(self._contains(points), -distance, distance)

    def _contains(self, points: FloatArray) -> NDArray[np.bool_]:
        """Which points are inside the object: inside any of its shells (trimesh's ray test)."""
        inside = np.zeros(len(points), dtype=bool)
        for shell in self.shells:
            inside |= np.asarray(shell.contains(points), dtype=bool)
        return inside

    def _links(
        self, touching: set[str], centres: FloatArray
    ) -> tuple[float, float, str, list[str]]:
        deepest, clearance, closest = 0.0, math.inf, ""
        problems = []
        request, collide = coal.DistanceRequest(), coal.CollisionRequest()
        far: list[tuple[float, int]] = []
        # How far each link's box centre is outside the object's box, per axis: a link whose
        # ball misses the box is far.
        outside = np.maximum(self.low - centres, 0.0) + np.maximum(centres - self.high, 0.0)
        missing = (outside > self.link_radii[:, None]).any(axis=1).tolist()
        for k, (g, oMg) in enumerate(
            zip(self.geometry.geometryObjects, self.geometry_data.oMg, strict=True)
        ):
            link = self.links[k]
            if link in touching:
                continue
            if missing[k]:
                far.append((float(np.linalg.norm(outside[k])) - self.link_radii[k], k))
                continue
            placed = coal.Transform3s(oMg.rotation, oMg.translation)
            hit = coal.collide(
                g.geometry, placed, self.bvh, self.identity, collide, coal.CollisionResult()
            )
            if hit:
                distance = -self._depth(k, oMg)
            elif self._inside(oMg.translation):  # wholly inside: as deep as its origin at least
                distance = float(self._signed_distance(np.array([oMg.translation]))[0])
            else:
                distance = coal.distance(
                    g.geometry, placed, self.bvh, self.identity, request, coal.DistanceResult()
                )
            if distance < clearance:
                clearance, closest = float(distance), link
            deepest = max(deepest, -distance)
            if -distance > self.tolerance_m:
                problems.append(f"link {link} {-1e3 * distance:.3f} mm inside the object")
        # Links away from the object's box: their exact distance only where it could be the least.
        for gap, k in sorted(far):
            if gap >= clearance:
                break
            oMg = self.geometry_data.oMg[k]
            distance = coal.distance(
                self.geometry.geometryObjects[k].geometry,
                coal.Transform3s(oMg.rotation, oMg.translation),
                self.bvh, self.identity, request, coal.DistanceResult(),
            )  # fmt: skip
            if distance < clearance:
                clearance, closest = float(distance), self.links[k]
        return deepest, clearance, closest, problems

    def _inside(self, point: FloatArray) -> bool:
        """Whether ``point`` is inside the mesh (trimesh's ray test, retrying ambiguous rays)."""
        return bool(self._contains(np.asarray(point, dtype=np.float64)[None])[0])

    def _depth(self, k: int, oMg: pin.SE3) -> float:
        """How deep link ``k``'s shape crosses into the object [m] (module docstring, 3)."""
        points = self.samples[k] @ oMg.rotation.T + oMg.translation
        near = np.all((points >= self.low - 1e-3) & (points <= self.high + 1e-3), axis=1)
        depth = 0.0
        if near.any():
            depth = max(depth, float(-self._signed_distance(points[near]).min()))
        local = (self.vertices - oMg.translation) @ oMg.rotation
        depth = max(depth, _depth_inside(self.geometry.geometryObjects[k].geometry, local))
        return depth

    def _self_collisions(self, centres: FloatArray) -> list[str]:
        out = []
        request = coal.CollisionRequest()
        objects = self.geometry.geometryObjects
        # Only pairs whose bounding spheres meet can collide: the rest need no coal query.
        a_idx, b_idx = self.pair_array[:, 0], self.pair_array[:, 1]
        gaps = np.linalg.norm(centres[a_idx] - centres[b_idx], axis=1)
        near = gaps <= self.link_radii[a_idx] + self.link_radii[b_idx]
        for a, b in self.pair_array[near].tolist():
            ta, tb = self.geometry_data.oMg[a], self.geometry_data.oMg[b]
            if coal.collide(
                objects[a].geometry,
                coal.Transform3s(ta.rotation, ta.translation),
                objects[b].geometry,
                coal.Transform3s(tb.rotation, tb.translation),
                request,
                coal.CollisionResult(),
            ):
                out.append(f"self-collision {self.links[a]} / {self.links[b]}")
        return out


def _mimic_joints(urdf: str) -> dict[str, tuple[str, float, float]]:
    """URDF mimic joints: name -> (leader, multiplier, offset)."""
    out = {}
    for joint in ET.parse(urdf).getroot().iter("joint"):
        mimic = joint.find("mimic")
        if mimic is not None:
            out[joint.get("name", "")] = (
                mimic.get("joint", ""),
                float(mimic.get("multiplier", "1")),
                float(mimic.get("offset", "0")),
            )
    return out


def _checked_pairs(
    model: pin.Model, objects: Any, links: list[str], description: HandDescription
) -> list[tuple[int, int]]:
    excluded = {frozenset(p) for p in description.excluded_collisions}
    parents = model.parents
    pairs = []
    for a in range(len(objects)):
        for b in range(a + 1, len(objects)):
            ja, jb = objects[a].parentJoint, objects[b].parentJoint
            if ja == jb or parents[ja] == jb or parents[jb] == ja:
                continue
            if frozenset((links[a], links[b])) in excluded:
                continue
            pairs.append((a, b))
    return pairs


def _grid(lo: float, hi: float) -> FloatArray:
    count = max(2, math.ceil((hi - lo) / _SAMPLE_SPACING_M) + 1)
    return np.linspace(lo, hi, count)


def _surface_samples(shape: Any) -> FloatArray:
    """Points spread over a collision shape's surface, at most 1 mm apart, shape frame."""
    if isinstance(shape, coal.Box):
        h = np.asarray(shape.halfSide)
        out = []
        for axis in range(3):
            u, v = [i for i in range(3) if i != axis]
            gu, gv = np.meshgrid(_grid(-h[u], h[u]), _grid(-h[v], h[v]), indexing="ij")
            for sign in (-1.0, 1.0):
                p = np.zeros((gu.size, 3))
                p[:, axis], p[:, u], p[:, v] = sign * h[axis], gu.ravel(), gv.ravel()
                out.append(p)
        return np.concatenate(out)
    if isinstance(shape, coal.Sphere):
        count = max(20, math.ceil(4 * math.pi * shape.radius**2 / _SAMPLE_SPACING_M**2))
        return shape.radius * _fibonacci(count)
    if isinstance(shape, coal.Cylinder | coal.Capsule):
        r, half = shape.radius, shape.halfLength
        angles = np.linspace(
            0.0, 2 * math.pi, max(8, math.ceil(2 * math.pi * r / _SAMPLE_SPACING_M)), endpoint=False
        )
        ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        out = [np.column_stack([r * ring, np.full(len(ring), z)]) for z in _grid(-half, half)]
        for radius in _grid(0.0, r)[:-1]:
            for z in (-half, half):
                out.append(np.column_stack([radius * ring, np.full(len(ring), z)]))
        if isinstance(shape, coal.Capsule):
            ball = r * _fibonacci(max(20, math.ceil(4 * math.pi * r * r / _SAMPLE_SPACING_M**2)))
            out += [ball + np.array([0.0, 0.0, half]), ball - np.array([0.0, 0.0, half])]
        return np.concatenate(out)
    if isinstance(shape, coal.ConvexBase):
        return np.asarray(shape.points(), dtype=np.float64)
    raise TypeError(f"no surface samples for a {type(shape).__name__} collision shape")


def _fibonacci(count: int) -> FloatArray:
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    phi = math.pi * (1.0 + 5**0.5) * i
    r = np.sqrt(1.0 - z * z)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


def _depth_inside(shape: Any, local: FloatArray) -> float:
    """Deepest of the points ``local`` (shape frame) inside the shape, below its surface [m]."""
    if isinstance(shape, coal.Box):
        h = np.asarray(shape.halfSide)
        margin = (h - np.abs(local)).min(axis=1)
    elif isinstance(shape, coal.Sphere):
        margin = shape.radius - np.linalg.norm(local, axis=1)
    elif isinstance(shape, coal.Cylinder):
        radial = shape.radius - np.linalg.norm(local[:, :2], axis=1)
        margin = np.minimum(radial, shape.halfLength - np.abs(local[:, 2]))
    elif isinstance(shape, coal.Capsule):
        axial = np.clip(local[:, 2], -shape.halfLength, shape.halfLength)
        offset = local - np.column_stack([np.zeros((len(local), 2)), axial])
        margin = shape.radius - np.linalg.norm(offset, axis=1)
    else:
        return 0.0
    return float(max(margin.max(initial=0.0), 0.0))
