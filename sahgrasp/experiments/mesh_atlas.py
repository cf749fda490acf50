"""The atlas on a mesh: each component of feasible grasps around given starts, verified on it.

Rosales, Porta and Ros (RSS 2011) optimise over the grasps whose contacts stay on given contact
regions of an analytic object. On a mesh the regions are smooth local models of the mesh around
each start's contacts (:func:`sahgrasp.optimization.grasp.mesh_patches`, docs/atlas.md "The atlas on
a mesh"); :func:`optimize_mesh_grasps` builds the atlas of R (Eq. (11)) from each start, checks
collisions at every chart centre as for the can (self-collision, and every link against the object's
collision pieces with the contact fingertips allowed ``d_min`` deep), and returns per connected
component the best grasp on the chosen index that passes a verification on the true mesh:
:func:`verify_grasp` (every contact within ``d_min`` of the mesh, no link inside the object, no
self-collision, joints within their limits). A start whose grasp lies in a component already
covered (its contacts on that component's regions and, brought onto its R, within one chart
radius of one of its chart centres) adds no atlas: each component is covered once.
:func:`read_starts` reads the starts from a planner's grasps (``{"grasps": [...]}``) or a targets
file (``{"problems": [...]}``).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from sahgrasp.core.errors import InvalidTargetError, OptimizationError, SahGraspError
from sahgrasp.core.fileio import read_json
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.experiments.arguments import MESH_DEFAULTS
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import CONTACT_ALLOWANCE_M, GraspObject, HandObjectClearance
from sahgrasp.objects.smooth_surface import MeshPatch
from sahgrasp.optimization.grasp import HandGraspManifold, make_mesh_manifold, mesh_patches
from sahgrasp.optimization.optimizer import OptimizationResult, OptimizationSettings, optimize

__all__ = [
    "MeshAtlasSearch",
    "MeshComponent",
    "MeshStart",
    "Verification",
    "optimize_mesh_grasps",
    "read_starts",
    "verify_grasp",
]


_VERIFY_TRIES = 50  # valid charts, best first, tried until one passes the verification


@dataclass(frozen=True)
class MeshStart:
    """A starting grasp: its contacts (world frame) and, if known, the hand there.

    Attributes:
        target: One contact per touching finger (two or more), on the placed object.
        q: The hand configuration (world frame), or None: the IK solves ``target``.
        label: Where it came from (``grasps[3]``, a problem's name).
    """

    target: GraspTarget
    q: np.ndarray | None
    label: str


@dataclass(frozen=True)
class Verification:
    """A grasp checked on the true mesh, independently of the atlas's models.

    Attributes:
        contact_distances_m: Per touching finger, the distance from its contact point to the
            mesh surface [m].
        penetrated: A link is inside the object (a contact fingertip deeper than ``d_min``).
        self_collision: Two links of the hand collide.
        within_limits: Every joint within its limits.
        d_min_m: The contact tolerance ``d_min`` [m].
    """

    contact_distances_m: dict[str, float]
    penetrated: bool
    self_collision: bool
    within_limits: bool
    d_min_m: float

    @property
    def ok(self) -> bool:
        """Every check passed."""
        near = all(d <= self.d_min_m for d in self.contact_distances_m.values())
        return near and not self.penetrated and not self.self_collision and self.within_limits


@dataclass(frozen=True)
class MeshComponent:
    """One connected component of R, its atlas and its best verified grasp.

    Attributes:
        problem: The grasp manifold (its regions: the smooth models around the first start).
        starts: The starts that fell in it (indices into the starts given), the first built it.
        result: Algorithm 1 on it (atlas, values, checks).
        start_value: The index at the first start, brought onto R (chart 0).
        best_chart: The best valid chart that passed :func:`verify_grasp` (None: none did).
        q_world: The hand at ``best_chart`` in the world frame (free fingers placed), or None.
        contacts: Its contacts (world frame, points on the model of the mesh).
        verification: Its verification (None when no chart passed).
    """

    problem: HandGraspManifold
    starts: tuple[int, ...]
    result: OptimizationResult
    start_value: float
    best_chart: int | None
    q_world: np.ndarray | None
    contacts: tuple[ContactTarget, ...]
    verification: Verification | None

    @property
    def best_value(self) -> float:
        """The index at the best verified grasp (NaN when none)."""
        chart = self.best_chart
        return math.nan if chart is None else float(self.result.all_values[chart])


@dataclass(frozen=True)
class MeshAtlasSearch:
    """:func:`optimize_mesh_grasps`'s outcome.

    Attributes:
        components: One per connected component reached, in the order of their first start.
        start_components: Per start, its component (None: the start could not be used).
        start_errors: Per start, why it could not be used (None when it could).
    """

    components: tuple[MeshComponent, ...]
    start_components: tuple[int | None, ...]
    start_errors: tuple[str | None, ...]


def verify_grasp(
    hand: Hand,
    obj: GraspObject,
    q_world: np.ndarray,
    fingers: Sequence[str],
    d_min_m: float = CONTACT_ALLOWANCE_M,
) -> Verification:
    """Check a grasp on the true mesh: contacts on its surface, nothing inside, no collision.

    Args:
        hand: The hand.
        obj: The object, placed in the world.
        q_world: The hand configuration (world frame).
        fingers: The touching fingers (their fingertip spheres may enter ``d_min_m`` deep).
        d_min_m: The contact tolerance [m].
    """
    import trimesh

    mesh = obj.mesh()
    tm = trimesh.Trimesh(mesh.vertices_m, mesh.faces, process=False)
    T_object_world = np.linalg.inv(obj.T_world_object)
    points = np.array([hand.contact_placement(q_world, f).translation for f in fingers])
    local = points @ T_object_world[:3, :3].T + T_object_world[:3, 3]
    _, distances, _ = trimesh.proximity.closest_point(tm, local)
    clearance = HandObjectClearance(hand, obj)
    return Verification(
        {f: float(d) for f, d in zip(fingers, distances, strict=True)},
        clearance.penetrated(q_world, fingers, allowance_m=d_min_m),
        hand.in_collision(q_world),
        hand.within_limits(q_world),
        d_min_m,
    )


def _world_grasp(
    problem: HandGraspManifold, result: OptimizationResult, chart: int, obj: GraspObject
) -> tuple[np.ndarray, tuple[ContactTarget, ...]]:
    """The hand and the contacts of ``chart`` in the world frame."""
    system = problem.system
    x = problem.x_of(result.atlas.centres[chart])
    q = result.configurations[chart].copy()  # palm at the origin
    T_palm_object = system.object_pose(x)
    T_world_palm = pin.SE3(obj.T_world_object) * T_palm_object.inverse()
    system.hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(T_world_palm)
    rotation, origin = obj.T_world_object[:3, :3], obj.T_world_object[:3, 3]
    contacts = []
    for c in system.contacts:
        jet = c.region.evaluate(x[c.params])  # object frame
        contacts.append(
            ContactTarget(c.finger, rotation @ jet.point + origin, rotation @ jet.normal)
        )
    return q, tuple(contacts)


def _component(
    hand: Hand,
    obj: GraspObject,
    problem: HandGraspManifold,
    result: OptimizationResult,
    starts: tuple[int, ...],
) -> MeshComponent:
    """The component's best chart that passes :func:`verify_grasp`."""
    fingers = [c.finger for c in problem.system.contacts]
    values = np.where(result.valid, result.all_values, -np.inf)
    order = np.argsort(-values, kind="stable")[:_VERIFY_TRIES]
    for chart in order.tolist():
        if not np.isfinite(values[chart]):
            break
        q, contacts = _world_grasp(problem, result, chart, obj)
        verification = verify_grasp(hand, obj, q, fingers)
        if verification.ok:
            return MeshComponent(problem, starts, result, float(result.all_values[0]), chart, q,
                                 contacts, verification)  # fmt: skip
    return MeshComponent(problem, starts, result, float(result.all_values[0]), None, None, (), None)


def _in_component(
    problem: HandGraspManifold, result: OptimizationResult, start: MeshStart, obj: GraspObject
) -> bool:
    """Whether ``start`` lies in the component ``result`` covers (see the module)."""
    system = problem.system
    if {c.finger for c in system.contacts} != set(start.target.fingers) or start.q is None:
        return False
    T_object_world = np.linalg.inv(obj.T_world_object)
    q = start.q.copy()
    T_object_palm = pin.SE3(T_object_world) * system.hand.wrist_pose(q)
    system.hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(T_object_palm)
    x = system.point(q)
    for c in system.contacts:
        region = c.region
        if not isinstance(region, MeshPatch):
            return False
        contact = start.target.contact(c.finger)
        local = region.frame.T @ (T_object_world[:3, :3] @ contact.point + T_object_world[:3, 3]
                                  - region.origin)  # fmt: skip
        if np.any(np.abs(local[:2]) > region.half_width_m):
            return False
        x[c.params] = local[:2]
    y = x / problem.scales
    lower, upper = problem.bounds()
    for _ in range(30):  # onto R by minimum-norm Newton steps
        residual = problem.F(y)
        if np.linalg.norm(residual) <= 1e-10:
            break
        y = y - np.linalg.lstsq(problem.J(y), residual, rcond=None)[0]
    else:
        return False
    if not np.all((y >= lower) & (y <= upper)):
        return False
    atlas = result.atlas
    return bool(np.min(np.linalg.norm(atlas.centres - y, axis=1)) <= atlas.radius)


def optimize_mesh_grasps(
    hand: Hand,
    obj: GraspObject,
    starts: Sequence[MeshStart],
    settings: OptimizationSettings | None = None,
    k: int = 2,
    length_scale_m: float = MESH_DEFAULTS["length_scale_m"],
    unit_m: float = MESH_DEFAULTS["unit_m"],
    motion_samples: int = 2000,
    seed: int = 0,
    progress: ProgressCallback | None = None,
) -> MeshAtlasSearch:
    """Algorithm 1 on a mesh object from each start; the best verified grasp of every component.

    Args:
        hand: The hand.
        obj: The object (a mesh, placed in the world).
        starts: Starting grasps (their contacts on the mesh).
        settings: Radius, epsilon (in the scaled coordinates), index, cap, workers; default
            :data:`MESH_DEFAULTS`' radius and epsilon with the volume index.
        k: Dimension of the relevant-grasp set R.
        length_scale_m: See :func:`sahgrasp.optimization.grasp.make_mesh_manifold`.
        unit_m: See :func:`sahgrasp.optimization.grasp.make_mesh_manifold`.
        motion_samples: Hand configurations sampled for the principal motions.
        seed: Seed of those samples.
        progress: Hears of ``("mesh atlas: starts", done, len(starts))``.

    Returns:
        The components; a start that cannot be used (no smooth model around a contact, no IK
        solution, no first grasp inside the bounds, a fourth contact finger that leaves t < k)
        gets its reason in ``start_errors``.

    Raises:
        OptimizationError: No start could be used.
    """
    settings = settings or OptimizationSettings(MESH_DEFAULTS["radius"], MESH_DEFAULTS["epsilon"])
    built: list[tuple[HandGraspManifold, OptimizationResult, list[int]]] = []
    owners: list[int | None] = []
    errors: list[str | None] = []
    for i, start in enumerate(starts):
        owner = next((j for j, (problem, result, _) in enumerate(built)
                      if _in_component(problem, result, start, obj)), None)  # fmt: skip
        error = None
        if owner is None:
            try:
                patches = mesh_patches(obj, start.target)
                problem = make_mesh_manifold(
                    hand, obj, start.target, start.q, k, motion_samples, seed, length_scale_m,
                    unit_m, patches,
                )  # fmt: skip
                result = optimize(problem, settings)
            except SahGraspError as exc:
                error = f"{start.label}: {exc}"
            else:
                built.append((problem, result, []))
                owner = len(built) - 1
        if owner is not None:
            built[owner][2].append(i)
        owners.append(owner)
        errors.append(error)
        if progress is not None:
            progress("mesh atlas: starts", i + 1, len(starts))
    if not built:
        raise OptimizationError(
            "no start could be used: " + "; ".join(e for e in errors if e is not None)
        )
    components = tuple(_component(hand, obj, p, r, tuple(s)) for p, r, s in built)
    return MeshAtlasSearch(components, tuple(owners), tuple(errors))


def _grasp_q(hand: Hand, item: dict[str, Any], where: str) -> np.ndarray | None:
    """The hand of a grasp entry (``wrist``, ``joints``, optional ``contact_params``), or None."""
    if item.get("wrist") is None or item.get("joints") is None:
        return None
    wrist, joints = item["wrist"], item["joints"]
    try:
        xyz = np.asarray(wrist["xyz"], dtype=np.float64).reshape(3)
        quat = np.asarray(wrist["quat"], dtype=np.float64).reshape(4)
        coords = {str(k): float(v) for k, v in dict(joints).items()}
        for finger, pair in dict(item.get("contact_params") or {}).items():
            pitch, yaw = (float(a) for a in pair)
            coords[f"{finger}_contact_pitch"], coords[f"{finger}_contact_yaw"] = pitch, yaw
    except (KeyError, TypeError, ValueError) as exc:
        raise InvalidTargetError(f"{where}: bad wrist, joints or contact_params ({exc})") from None
    if not (
        np.isfinite(xyz).all() and np.isfinite(quat).all() and abs(np.linalg.norm(quat) - 1) < 1e-6
    ):
        raise InvalidTargetError(f"{where}: wrist xyz and quat must be finite, quat of unit length")
    known = set(hand.coordinate_names)
    mimic = set(hand.mimic_joints)
    unknown = sorted(set(coords) - known - mimic)
    if unknown:
        raise InvalidTargetError(f"{where}: unknown joint(s) {unknown} for this hand")
    T = pin.XYZQUATToSE3(np.concatenate([xyz, quat]))
    return hand.configuration(T, {k: v for k, v in coords.items() if k in known})


def read_starts(path: str | os.PathLike[str], hand: Hand) -> list[MeshStart]:
    """Starting grasps from a planner's grasps or a targets file (world frame, SI units).

    ``{"grasps": [{"contacts": [{"finger", "point", "normal"}], "wrist": {"xyz", "quat"},
    "joints": {...}, "contact_params": {...}}, ...]}`` (``sahgrasp plan``; the hand is optional
    per grasp) or ``{"problems": [{"name", "contacts"}, ...]}`` (a targets file: the IK solves each
    start). Each needs two or more contacts.

    Raises:
        InvalidTargetError: The file is not of either form, or an entry is malformed.
    """
    data = read_json(path, "starts file", InvalidTargetError)
    if not isinstance(data, dict) or not ({"grasps", "problems"} & data.keys()):
        raise InvalidTargetError(
            f"starts file {path}: need a JSON object with 'grasps' (sahgrasp plan) or 'problems' "
            "(a targets file)"
        )
    key = "grasps" if "grasps" in data else "problems"
    entries = data[key]
    if not isinstance(entries, list) or not entries:
        raise InvalidTargetError(f"starts file {path}: '{key}' must be a non-empty list")
    starts = []
    for i, item in enumerate(entries):
        where = f"starts file {path}, {key}[{i}]"
        if not isinstance(item, dict):
            raise InvalidTargetError(f"{where}: must be an object")
        label = str(item.get("name", f"{key}[{i}]"))
        target = GraspTarget.from_dict(
            {"name": label, "contacts": item.get("contacts")}, Path(path).parent
        )
        if len(target.contacts) < 2:
            raise InvalidTargetError(f"{where}: a start needs two or more contacts")
        target.check_fingers([f for f in hand.fingers if f in target.fingers])
        starts.append(MeshStart(target, _grasp_q(hand, item, where), label))
    return starts
