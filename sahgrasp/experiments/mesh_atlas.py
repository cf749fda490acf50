"""The atlas on a mesh: each component of feasible grasps around given starts, verified on it.

Rosales, Porta and Ros (RSS 2011) optimise over the grasps whose contacts stay on given contact
regions of an analytic object. On a mesh the regions are smooth local models of the mesh around
each start's contacts, anchored there (:func:`start_patches`; docs/methods/atlas.md "The atlas on a
mesh", Eqs. (M1)-(M4)): the start is the atlas's first chart. :func:`optimize_mesh_grasps`
builds the atlas of R (Eq. (11)) from each start, checks collisions at every chart centre as for
the can (self-collision, and every link against the object's collision pieces with the contact
fingertips allowed ``d_min`` deep), and returns per connected component the best grasp on the
chosen index that passes two verifications on the true mesh: :func:`verify_grasp` (every contact
within ``d_min`` of the mesh, no link inside the object, no self-collision, joints within their
limits) and the planner's independent verifier
(:class:`~sahgrasp.planner.verify.GraspVerifier`, as every planned grasp). A start whose grasp
lies in a component already covered (its contacts on that component's regions and, brought onto
its R, within one chart radius of one of its chart centres) adds no atlas: each component is
covered once. :func:`refine_mesh_grasp` builds rounds of atlases, each from the last one's
optimum. :func:`read_starts` reads the starts from a planner's grasps (``{"grasps": [...]}``) or
a targets file (``{"problems": [...]}``).
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

from sahgrasp.core.errors import (
    InvalidSettingsError,
    InvalidTargetError,
    OptimizationError,
    SahGraspError,
)
from sahgrasp.core.fileio import read_json
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.experiments.arguments import MESH_DEFAULTS
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import CONTACT_ALLOWANCE_M, GraspObject, HandObjectClearance
from sahgrasp.objects.patches import GraspPatches
from sahgrasp.objects.smooth_surface import MeshPatch
from sahgrasp.objects.targets import problem_from_dict
from sahgrasp.optimization import OptimizationResult, OptimizationSettings, optimize
from sahgrasp.optimization.grasp import HandGraspManifold, make_mesh_manifold, mesh_patches
from sahgrasp.planner.pieces import planning_object
from sahgrasp.planner.verify import LINK_TOLERANCE_M, GraspVerifier, Verdict

__all__ = [
    "MAX_HALF_WIDTH_M",
    "MODEL_TOLERANCE_M",
    "MeshAtlasSearch",
    "MeshComponent",
    "MeshStart",
    "Verification",
    "mesh_verifier",
    "optimize_mesh_grasps",
    "read_starts",
    "refine_mesh_grasp",
    "start_patches",
    "verify_grasp",
]


MAX_HALF_WIDTH_M = 0.02
"""Largest half width of a contact region around a start's contact [m]."""
MODEL_TOLERANCE_M = 3e-4
"""Largest distance of a region's smooth model from the mesh [m]."""

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
        contacts: Its contacts (world frame): the model's contact points moved to the closest
            point of the true mesh, with the model's normal.
        verification: Its verification by :func:`verify_grasp` (None when no chart passed).
        verdict: Its verification by the planner's independent verifier
            (:class:`sahgrasp.planner.verify.GraspVerifier`, as every planned grasp is
            checked), None when no chart passed.
        verified_tries: Valid charts checked, best first, before one passed (or all tried).
        model_contacts: The best grasp's contacts on the smooth models (world frame), where its
            contact frames are: a further round anchored there starts exactly at that grasp.
    """

    problem: HandGraspManifold
    starts: tuple[int, ...]
    result: OptimizationResult
    start_value: float
    best_chart: int | None
    q_world: np.ndarray | None
    contacts: tuple[ContactTarget, ...]
    verification: Verification | None
    verdict: Verdict | None = None
    verified_tries: int = 0
    model_contacts: tuple[ContactTarget, ...] = ()

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


def start_patches(
    obj: GraspObject,
    target: GraspTarget,
    max_half_width_m: float = MAX_HALF_WIDTH_M,
    tolerance_m: float = MODEL_TOLERANCE_M,
) -> GraspPatches:
    """Contact regions around a start's contacts: smooth models anchored at each contact.

    As :func:`sahgrasp.optimization.grasp.mesh_patches`, but each model passes through its contact
    point with the contact's normal (``fit_mesh_patch(..., anchored=True)``): a start that reaches
    its contacts is on F as it is, so the atlas's first chart is the start itself and the optimum
    is never worse than the start.

    Raises:
        SurfaceModelError: No smooth model of the mesh fits around a contact.
    """
    return mesh_patches(obj, target, max_half_width_m, tolerance_m, anchored=True)


def _on_mesh(
    contacts: tuple[ContactTarget, ...], verifier: GraspVerifier
) -> tuple[ContactTarget, ...]:
    """The contacts with their points moved to the closest point of the true mesh."""
    moved = []
    for c in contacts:
        point, _, _ = verifier.surface.closest(np.asarray(c.point, dtype=np.float64))
        moved.append(ContactTarget(c.finger, point, c.normal))
    return tuple(moved)


def _component(
    hand: Hand,
    obj: GraspObject,
    problem: HandGraspManifold,
    result: OptimizationResult,
    starts: tuple[int, ...],
    verifier: GraspVerifier,
) -> MeshComponent:
    """The component's best chart that passes :func:`verify_grasp` and ``verifier``.

    The smooth models are within their tolerance of the mesh, not on it: the contacts are
    checked at their closest points of the true mesh (the fingertip within ``d_min`` of
    ``point + radius * normal`` there, as for a planned grasp).
    """
    fingers = [c.finger for c in problem.system.contacts]
    values = np.where(result.valid, result.all_values, -np.inf)
    order = np.argsort(-values, kind="stable")[:_VERIFY_TRIES]
    start_value = float(result.all_values[0])
    tries = 0
    for chart in order.tolist():
        if not np.isfinite(values[chart]):
            break
        tries += 1
        q, contacts = _world_grasp(problem, result, chart, obj)
        verification = verify_grasp(hand, obj, q, fingers)
        if not verification.ok:
            continue
        on_mesh = _on_mesh(contacts, verifier)
        wrist = {"xyz": q[:3].tolist(), "quat": q[3:7].tolist()}
        verdict = verifier.check(wrist, hand.joint_values(q), [c.to_dict() for c in on_mesh])
        if verdict.ok:
            return MeshComponent(problem, starts, result, start_value, chart, q, on_mesh,
                                 verification, verdict, tries, contacts)  # fmt: skip
    return MeshComponent(problem, starts, result, start_value, None, None, (), None, None, tries)


def mesh_verifier(
    hand: Hand,
    obj: GraspObject,
    d_min_m: float = CONTACT_ALLOWANCE_M,
    tolerance_m: float = LINK_TOLERANCE_M,
) -> GraspVerifier:
    """The planner's independent verifier of grasps of ``obj`` (its true mesh, world frame)."""
    mesh = obj.mesh().transformed(obj.T_world_object)
    return GraspVerifier(hand.description, mesh.vertices_m, mesh.faces, d_min_m, tolerance_m)


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
    max_half_width_m: float = MAX_HALF_WIDTH_M,
    tolerance_m: float = MODEL_TOLERANCE_M,
    verifier: GraspVerifier | None = None,
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
        max_half_width_m: Largest half width of a contact region [m] (:func:`start_patches`).
        tolerance_m: Largest distance of a region's model from the mesh [m].
        verifier: The independent verifier of the optimum (default: :func:`mesh_verifier`).

    Returns:
        The components; a start that cannot be used (no smooth model around a contact, no IK
        solution, no first grasp inside the bounds, a fourth contact finger that leaves t < k)
        gets its reason in ``start_errors``.

    Raises:
        OptimizationError: No start could be used.
    """
    settings = settings or OptimizationSettings(MESH_DEFAULTS["radius"], MESH_DEFAULTS["epsilon"])
    # The collision checks at the chart centres use the planner's pieces (the triangles' prisms,
    # unjoined): the same solid as the joined pieces, built in a fraction of the time.
    obj = planning_object(obj)
    built: list[tuple[HandGraspManifold, OptimizationResult, list[int]]] = []
    owners: list[int | None] = []
    errors: list[str | None] = []
    for i, start in enumerate(starts):
        owner = next((j for j, (problem, result, _) in enumerate(built)
                      if _in_component(problem, result, start, obj)), None)  # fmt: skip
        error = None
        if owner is None:
            try:
                patches = start_patches(obj, start.target, max_half_width_m, tolerance_m)
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
    verifier = verifier or mesh_verifier(hand, obj)
    components = tuple(_component(hand, obj, p, r, tuple(s), verifier) for p, r, s in built)
    return MeshAtlasSearch(components, tuple(owners), tuple(errors))


def refine_mesh_grasp(
    hand: Hand,
    obj: GraspObject,
    start: MeshStart,
    settings: OptimizationSettings | None = None,
    rounds: int = 3,
    **options: Any,
) -> tuple[MeshComponent, ...]:
    """Rounds of :func:`optimize_mesh_grasps`, each from the previous round's verified optimum.

    One atlas covers the grasps whose contacts stay on regions at most ``2 * max_half_width_m``
    wide around the start's; when its best verified grasp lies away from the start, new regions
    around that grasp's contacts (its points on the true mesh, its model normals) reach further.
    Each round is a complete atlas and its optimum passes the same verifications. A round starts
    at the last optimum as it is (its regions anchored at that grasp's contact points on the
    models, within their tolerance of the mesh). The rounds stop when a round's best verified
    grasp is its first chart (the start), when no chart passes the verification, when a round
    finds nothing better than the last (that round is dropped), or when a round's start cannot
    be used (its error is not raised: the rounds before it stand).

    Args:
        hand: The hand.
        obj: The object, placed in the world.
        start: The first round's start.
        settings: See :func:`optimize_mesh_grasps`.
        rounds: Most rounds (>= 1).
        **options: Further arguments of :func:`optimize_mesh_grasps`.

    Returns:
        The component of each round kept, in order; each better than the last, so the last
        holds the best grasp (its ``q_world`` is None only when the first round found none).

    Raises:
        OptimizationError: The first start cannot be used.
        InvalidSettingsError: ``rounds`` < 1.
    """
    if isinstance(rounds, bool) or not isinstance(rounds, int) or rounds < 1:
        raise InvalidSettingsError(f"rounds must be an integer >= 1, got {rounds!r}")
    done: list[MeshComponent] = []
    current = start
    for number in range(rounds):
        try:
            search = optimize_mesh_grasps(hand, obj, [current], settings, **options)
        except OptimizationError:
            if not done:
                raise
            break
        component = search.components[0]
        if done and not component.best_value > done[-1].best_value:
            break  # nothing better than the last round's optimum (its start)
        done.append(component)
        if component.q_world is None or component.best_chart in (None, 0):
            break
        # Anchored at the model's contact points (within the tolerance of the mesh), the next
        # round's first chart is this optimum as it is.
        target = GraspTarget(start.target.name, list(component.model_contacts))
        current = MeshStart(target, component.q_world, f"{start.label}, round {number + 2}")
    return tuple(done)


def _grasp_q(
    hand: Hand, item: dict[str, Any], where: str, target: GraspTarget
) -> np.ndarray | None:
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
    q = hand.configuration(T, {k: v for k, v in coords.items() if k in known})
    if not item.get("contact_params"):  # a plan gives none: the fingertip point at each contact
        q = _contact_params_at(hand, q, target)
    return q


_TIGHT = {"xtol": 1e-12, "ftol": 1e-12, "gtol": 1e-12}


def _contact_params_at(hand: Hand, q: np.ndarray, target: GraspTarget) -> np.ndarray:
    """``q`` with each contact finger's contact frame at its contact point.

    The virtual contact joints are fitted by least squares within their limits; the wrist and
    the URDF joints are left as they are.
    ``sahgrasp plan``'s grasps give the wrist and every URDF joint, not the virtual contact
    joints; the atlas's F needs them (its first chart is the start as given).
    """
    from scipy.optimize import least_squares

    q = q.copy()
    lower, upper = hand.model.lowerPositionLimit, hand.model.upperPositionLimit
    for contact in target.contacts:
        index = [
            7 + hand.coordinate_index(f"{contact.finger}_contact_{a}") for a in ("pitch", "yaw")
        ]
        low, high = lower[index], upper[index]

        def residual(p: np.ndarray, index: list[int] = index, finger: str = contact.finger,
                     point: np.ndarray = contact.point) -> np.ndarray:  # fmt: skip
            moved = q.copy()
            moved[index] = p
            # In millimetres: metre-sized residuals would meet least_squares' gradient tolerance
            # a tenth of a millimetre away.
            return 1e3 * (np.asarray(hand.contact_placement(moved, finger).translation) - point)

        best = None
        for guess in (np.clip(q[index], low, high), 0.5 * (low + high)):
            fit = least_squares(residual, guess, bounds=(low, high), **_TIGHT)
            if best is None or fit.cost < best.cost:
                best = fit
        assert best is not None
        q[index] = best.x
    return q


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
        target = problem_from_dict(
            {"name": label, "contacts": item.get("contacts")}, Path(path).parent
        )
        if len(target.contacts) < 2:
            raise InvalidTargetError(f"{where}: a start needs two or more contacts")
        target.check_fingers([f for f in hand.fingers if f in target.fingers])
        starts.append(MeshStart(target, _grasp_q(hand, item, where, target), label))
    return starts
