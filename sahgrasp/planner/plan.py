"""From an object to ranked, verified grasps: :func:`plan_grasps`.

For each candidate contact set (:mod:`sahgrasp.planner.candidates`; draws interleave the finger
counts of :attr:`PlanSettings.fingers`), the IK (:func:`sahgrasp.ik.solve_ik`) solves the contacts
with the object as an obstacle, the fingers without a contact placed clear of the object and of
the hand. Every solved grasp is then re-checked independently
(:class:`~sahgrasp.planner.verify.GraspVerifier`); only grasps that pass it are kept. Each kept
grasp has its force closure (the draw's exact test,
:func:`sahgrasp.quality.wrench.force_closure`), its L1 epsilon where the ranking needs it
(:func:`_select`) and the atlas paper's manipulability indices; the grasps are ranked (force
closure first, then by :attr:`PlanSettings.rank`), duplicates dropped (same fingers, wrists and
contacts within ``distinct_m``/``distinct_deg``), an optional extra check applied (e.g. a physics
test: it may drop a grasp or re-rank by its score), and the best :attr:`PlanSettings.grasps`
returned with their L-infinity epsilon.

The work done is a fixed number of candidates (:attr:`PlanSettings.candidates`), each drawn from a
seed derived from the plan's seed, the object's name and the draw's index: the same seed gives the
same plan whatever the machine, its load or the number of worker processes. With an extra check
and ``max_candidates``, the planner draws further batches of that many candidates (the draws
continuing where they stopped) while fewer grasps than asked pass the check, up to
``max_candidates`` in all: the work then depends on the check's verdicts, which are
deterministic too.
"""

from __future__ import annotations

import math
import time
import zlib
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.objects.body import GraspObject
from sahgrasp.objects.grasp_sampler import SurfaceMesh
from sahgrasp.planner.candidates import (
    Candidate,
    CandidateDraw,
    ObjectFrame,
    finger_set,
    hand_reach,
)
from sahgrasp.planner.pieces import planning_object
from sahgrasp.planner.settings import PlanningError, PlanSettings
from sahgrasp.planner.verify import GraspVerifier
from sahgrasp.quality.ellipsoids import INDICES, ellipsoid_indices, null_space
from sahgrasp.quality.weight import weight_supports
from sahgrasp.quality.wrench import epsilon, grasp_quality, primitive_wrenches

__all__ = [
    "GraspCheck",
    "GraspPlan",
    "PlanSummary",
    "PlannedGrasp",
    "manipulability_indices",
    "plan_grasps",
]

FloatArray = NDArray[np.float64]

GraspCheck = Callable[["PlannedGrasp"], "float | None"]
"""An extra check of a planned grasp: None drops it, a number (higher is better) re-ranks."""

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
LINF_MAX_POINTS = 125
"""The L-infinity epsilon is computed when its Minkowski sum has at most this many points
(``(linf_edges + 1) ** contacts``; its hull in six dimensions grows fast): with the default 3
edges, for grasps of 2 and 3 fingers; None for 4 fingers."""


@dataclass(frozen=True)
class PlannedGrasp:
    """One verified grasp of a plan (world frame, the object at its placement).

    Attributes:
        fingers: Fingers in contact, thumb first.
        contacts: Their contacts (point on the object, outward normal).
        q: The hand configuration (wrist + independent coordinates, :class:`sahgrasp.Hand`).
        joints: Every URDF joint's value [rad], mimic joints included.
        quality: ``force_closure``, ``epsilon_l1``, ``epsilon_linf`` (returned grasps; None
            before), and the manipulability indices by name (every verified grasp when ranked by
            one, else the grasps considered for the result); ``check`` when an extra check
            scored it.
        object_clearance_m: Smallest signed distance of a non-contact link to the mesh [m].
        closest_link: That link.
        seed: The draw's seed: the candidate (and the IK's starts) it reproduces.
        time_s: Seconds from the plan's start to this grasp's verification.
    """

    fingers: tuple[str, ...]
    contacts: tuple[ContactTarget, ...]
    q: FloatArray = field(repr=False)
    joints: dict[str, float]
    quality: dict[str, Any]
    object_clearance_m: float
    closest_link: str
    seed: int
    time_s: float = 0.0

    @property
    def force_closure(self) -> bool:
        """Whether the contacts are in force closure (hard fingers, the plan's ``mu``)."""
        return bool(self.quality["force_closure"])

    @property
    def wrist(self) -> dict[str, list[float]]:
        """The wrist pose as a results file holds it: ``xyz`` [m] and ``quat`` [x, y, z, w]."""
        return {"xyz": self.q[:3].tolist(), "quat": self.q[3:7].tolist()}

    def to_dict(self, rank: int) -> dict[str, Any]:
        """The JSON form of docs/how-to/file-formats.md ("Planned grasps")."""
        return {
            "rank": rank,
            "fingers": list(self.fingers),
            "contacts": [c.to_dict() for c in self.contacts],
            "wrist": self.wrist,
            "joints": dict(self.joints),
            "quality": dict(self.quality),
            "object_clearance_mm": 1e3 * self.object_clearance_m,
            "closest_link": self.closest_link,
            "seed": self.seed,
        }


@dataclass(frozen=True)
class PlanSummary:
    """Counts and times of a plan.

    Attributes:
        grasps: Grasps returned.
        force_closure: Of them, in force closure.
        candidates: Candidate contact sets solved with the IK.
        draws: Contact sets drawn (candidates and rejected draws).
        rejected: Draws rejected before the IK, by reason.
        solved: Candidates the IK solved.
        verified: Solved grasps that passed the independent verification.
        verified_force_closure: Of them, in force closure.
        failed_verification: Solved grasps the verification refused, by first problem.
        by_fingers: Verified grasps by finger count.
        time_to_first_s: Seconds from the start to the first verified force-closure grasp
            (None: none).
        time_s: Seconds of the whole plan from the start.
        time_limited: The time limit stopped the plan before its candidate budget.
    """

    grasps: int
    force_closure: int
    candidates: int
    draws: int
    rejected: dict[str, int]
    solved: int
    verified: int
    verified_force_closure: int
    failed_verification: dict[str, int]
    by_fingers: dict[str, int]
    time_to_first_s: float | None
    time_s: float
    time_limited: bool

    def to_dict(self) -> dict[str, Any]:
        """The JSON form."""
        return dict(self.__dict__)


@dataclass(frozen=True)
class GraspPlan:
    """Ranked, verified grasps of one object.

    Attributes:
        hand: The hand's name.
        object: The object as a targets file names it (``name`` or ``mesh``, ``xyz``, ``quat``).
        settings: The settings used.
        grasps: The grasps, best first.
        summary: Counts and times.
        repairs: What loading the mesh repaired (empty: nothing, or a catalog object).
    """

    hand: str
    object: dict[str, Any]
    settings: PlanSettings
    grasps: tuple[PlannedGrasp, ...]
    summary: PlanSummary
    repairs: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The plan document of docs/how-to/file-formats.md ("Planned grasps")."""
        obj = dict(self.object)
        if self.repairs:
            obj["repairs"] = list(self.repairs)
        return {
            "hand": self.hand,
            "object": obj,
            "settings": self.settings.to_dict(),
            "grasps": [g.to_dict(i + 1) for i, g in enumerate(self.grasps)],
            "summary": self.summary.to_dict(),
        }


def manipulability_indices(
    hand: Hand, q: FloatArray, fingers: tuple[str, ...], reference_m: FloatArray
) -> dict[str, float]:
    """The atlas paper's manipulability indices of a grasp (:mod:`sahgrasp.quality.ellipsoids`).

    Hard-finger velocity constraints at the contact frames (the fingertip's material point moves
    with the object's point there), ``J_h qdot - G^T nu = 0`` with ``qdot`` the actuated joints
    of the contact fingers and ``nu`` the object twist at ``reference_m``, world-aligned; the
    ellipsoid of object twists reachable with unit actuated velocity gives the indices
    (Bicchi and Prattichizzo 2000, as the atlas uses them: ``GraspSystem.hard_finger_constraints``).
    """
    model, data = hand.model, hand.model.createData()
    pin.computeJointJacobians(model, data, q)
    pin.updateFramePlacements(model, data)
    virtual = set(hand.virtual_joint_names)
    coords = sorted({int(i) for f in fingers for i in hand.finger_coordinates[f]})
    actuated = np.array([i for i in coords if hand.coordinate_names[i] not in virtual])
    columns = 6 + actuated
    a = len(actuated)
    C = np.zeros((3 * len(fingers), a + 6))
    for k, f in enumerate(fingers):
        frame = hand.contact_frame_id(f)
        J = pin.getFrameJacobian(model, data, frame, _LWA)
        arm = np.asarray(data.oMf[frame].translation) - reference_m
        rows = slice(3 * k, 3 * k + 3)
        C[rows, :a] = J[:3, columns]
        C[rows, a : a + 3] = -np.eye(3)
        C[rows, a + 3 :] = np.array(
            [[0.0, -arm[2], arm[1]], [arm[2], 0.0, -arm[0]], [-arm[1], arm[0], 0.0]]
        )
    motions = null_space(C, C.shape[1] - C.shape[0])
    indices = ellipsoid_indices(motions[:a], motions[a:])
    return {name: float(indices.index(name)) for name in INDICES}


def _object_key(obj: GraspObject) -> int:
    return zlib.crc32(obj.name.encode("utf-8"))


def draw_seed(seed: int, obj: GraspObject, index: int) -> int:
    """The seed of draw ``index`` of a plan of ``obj`` with ``seed``."""
    state = np.random.SeedSequence([seed, _object_key(obj), index]).generate_state(2, np.uint32)
    return int(state[0]) << 31 | int(state[1]) >> 1


def plan_grasps(
    hand: Hand | str,
    obj: GraspObject,
    settings: PlanSettings | None = None,
    *,
    object_spec: dict[str, Any] | None = None,
    check: GraspCheck | None = None,
    started: float | None = None,
    on_candidate: Callable[[], object] | None = None,
    max_candidates: int | None = None,
) -> GraspPlan:
    """Plan ranked, verified grasps of ``obj`` (module docstring, docs/methods/planner.md).

    Args:
        hand: The hand, or its name / description file.
        obj: The object, placed in the world (``load_mesh``, ``load_object``).
        settings: Planner settings (defaults: :class:`PlanSettings`).
        object_spec: How a targets file names the object, recorded in the plan (default: its
            name and placement).
        check: An extra check of the best grasps (e.g. a physics test), applied in rank order
            until enough grasps pass: None drops a grasp, a number re-ranks (higher first).
        started: ``time.perf_counter()`` at the user's start (a command's launch), for
            ``time_to_first_s`` and ``time_s``; default: this call's start.
        on_candidate: Called after each candidate is solved (progress).
        max_candidates: With ``check``: when fewer than ``settings.grasps`` grasps pass it
            after ``settings.candidates`` candidates, further batches of
            ``settings.candidates`` candidates are drawn (the draws continue where they
            stopped) and the check asked again, over all verified grasps in rank order, until
            enough pass or this many candidates were solved. None (or without a check): one
            batch. The draws' seeds do not depend on the batches, so a plan stays the same on
            any machine and worker count.

    Returns:
        The plan; an object without a reachable grasp gives a plan of no grasps (its summary
        says what was rejected), not an error.

    Raises:
        PlanningError: A finger count the hand does not have, or ``max_candidates`` < 1.
    """
    if max_candidates is not None and (
        isinstance(max_candidates, bool)
        or not isinstance(max_candidates, int)
        or max_candidates < 1
    ):
        raise PlanningError(f"max_candidates must be an integer >= 1, got {max_candidates!r}")
    start = time.perf_counter() if started is None else started
    settings = settings or PlanSettings()
    hand = hand if isinstance(hand, Hand) else load_hand(hand)
    try:
        sets = {k: finger_set(hand, k) for k in settings.fingers}
    except ValueError as exc:
        raise PlanningError(f"hand {hand.description.name}: {exc}") from None
    obj = planning_object(obj)
    mesh = obj.mesh().transformed(obj.T_world_object)
    surface = SurfaceMesh(mesh.vertices_m, mesh.faces)
    frame = ObjectFrame.of(
        surface.triangles.reshape(-1, 3), np.arange(3 * len(surface)).reshape(-1, 3)
    )
    draw = CandidateDraw(surface, hand_reach(hand), frame, settings.mu, edges=settings.cone_edges)
    verifier = GraspVerifier(
        hand.description, mesh.vertices_m, mesh.faces, settings.d_min_m, settings.link_tolerance_m
    )
    ik = IKSettings(max_inits=settings.ik_max_inits, d_min_m=settings.d_min_m)
    counts = settings.fingers
    # Two hard-finger contacts are never force closure: with other finger counts asked for too,
    # two-finger draws come once per cycle and the others twice (3, 4, 3, 4, 2).
    cycle = (
        tuple(k for k in counts if k != 2) * 2 + (2,) if 2 in counts and len(counts) > 1 else counts
    )
    rejected: Counter[str] = Counter()
    failed: Counter[str] = Counter()
    verified: list[PlannedGrasp] = []
    candidates = draws = 0
    first: float | None = None
    limited = False
    # Candidates of this batch and of all batches a check may ask for (module docstring).
    budget = settings.candidates
    cap = budget if check is None or max_candidates is None else max(budget, max_candidates)
    scores: dict[int, float | None] = {}  # the check's verdicts, by verified grasp's index
    while True:
        max_draws = budget * settings.max_draws_per_candidate
        while candidates < budget and draws < max_draws:
            if (
                settings.time_limit_s is not None
                and time.perf_counter() - start > settings.time_limit_s
            ):
                limited = True
                break
            seed = draw_seed(settings.seed, obj, draws)
            fingers = sets[cycle[draws % len(cycle)]]
            draws += 1
            candidate = draw.draw(fingers, seed)
            if isinstance(candidate, str):
                rejected[candidate] += 1
                continue
            candidates += 1
            grasp = _solve(hand, obj, candidate, ik, verifier, frame, settings, failed, start)
            if on_candidate is not None:
                on_candidate()
            if grasp is None:
                continue
            verified.append(grasp)
            if first is None and grasp.force_closure:
                first = grasp.time_s
        chosen = _select(hand, verified, settings, check, frame, scores)
        if (
            len(chosen) >= settings.grasps
            or budget >= cap
            or limited
            or candidates < budget  # the draws ran out: the object is given up
        ):
            break
        budget = min(budget + settings.candidates, cap)
    solved = len(verified) + failed.total()
    summary = PlanSummary(
        grasps=len(chosen),
        force_closure=sum(g.force_closure for g in chosen),
        candidates=candidates,
        draws=draws,
        rejected=dict(sorted(rejected.items())),
        solved=solved,
        verified=len(verified),
        verified_force_closure=sum(g.force_closure for g in verified),
        failed_verification=dict(sorted(failed.items())),
        by_fingers={str(k): sum(len(g.fingers) == k for g in verified) for k in counts},
        time_to_first_s=first,
        time_s=time.perf_counter() - start,
        time_limited=limited,
    )
    spec = object_spec or {
        "name": obj.name,
        "xyz": obj.T_world_object[:3, 3].tolist(),
        "quat": pin.Quaternion(obj.T_world_object[:3, :3]).coeffs().tolist(),
    }
    repairs = tuple(r for s in obj.solids for r in getattr(s, "repairs", ()))
    return GraspPlan(hand.description.name, spec, settings, tuple(chosen), summary, repairs)


def _solve(
    hand: Hand,
    obj: GraspObject,
    candidate: Candidate,
    ik: IKSettings,
    verifier: GraspVerifier,
    frame: ObjectFrame,
    settings: PlanSettings,
    failed: Counter[str],
    start: float,
) -> PlannedGrasp | None:
    """IK, verification and quality of one candidate; None when unsolved or refused."""
    contacts = tuple(
        ContactTarget(f, p, n)
        for f, p, n in zip(candidate.fingers, candidate.points_m, candidate.normals, strict=True)
    )
    free = tuple(f for f in hand.fingers if f not in candidate.fingers)
    target = GraspTarget(f"{obj.name}-{candidate.seed}", contacts)
    result = solve_ik(
        hand, target, ik, free_fingers=free, obstacle=obj, seed=candidate.seed % (2**31)
    )
    if not result.success:
        return None
    joints = hand.joint_values(result.q)
    wrist = {"xyz": result.q[:3].tolist(), "quat": result.q[3:7].tolist()}
    verdict = verifier.check(wrist, joints, [c.to_dict() for c in contacts])
    if not verdict.ok:
        failed[verdict.problems[0].split(" ")[0]] += 1
        return None
    # Force closure of the contact set the IK reached (the draw's exact test); its epsilon is
    # computed when the ranking needs it (_select).
    quality: dict[str, Any] = {
        "force_closure": candidate.force_closure,
        "epsilon_l1": None,
        "epsilon_linf": None,
    }
    # Ranked by the weight support, every verified grasp needs it: _select computes all of an
    # object's at once (one linear program). Ranked by an index, it is computed here.
    if settings.rank not in (
        "epsilon",
        "weight",
    ):  # ranked by an index: every verified grasp needs it
        quality.update(manipulability_indices(hand, result.q, candidate.fingers, frame.centroid_m))
    return PlannedGrasp(
        fingers=candidate.fingers,
        contacts=contacts,
        q=result.q,
        joints=joints,
        quality=quality,
        object_clearance_m=verdict.clearance_m,
        closest_link=verdict.closest_link,
        seed=candidate.seed,
        time_s=time.perf_counter() - start,
    )


def _choose(
    hand: Hand,
    grasps: list[tuple[int, PlannedGrasp]],
    settings: PlanSettings,
    check: GraspCheck | None,
    frame: ObjectFrame,
    scores: dict[int, float | None],
    complete: bool = True,
    indices: bool = True,
) -> list[tuple[float, int, PlannedGrasp]]:
    """The first distinct grasps in rank order that pass ``check`` (at most ``grasps``).

    Without ``complete``, the grasps not in ``grasps`` are force-closure grasps whose epsilon
    is not known yet: the grasps without force closure, which rank after all of them, wait.
    With ``indices``, the chosen grasps get their manipulability indices (a check may use them).
    """
    ranked = sorted(grasps, key=lambda e: (*_rank_key(e[1], settings.rank), e[0]))
    chosen: list[tuple[float, int, PlannedGrasp]] = []
    for order, grasp in ranked:
        if len(chosen) == settings.grasps or (not complete and not grasp.force_closure):
            break
        if any(_same(grasp, c, settings) for _, _, c in chosen):
            continue
        if (indices or check is not None) and INDICES[0] not in grasp.quality:
            # Ranked by epsilon: the indices of the grasps kept only.
            grasp.quality.update(
                manipulability_indices(hand, grasp.q, grasp.fingers, frame.centroid_m)
            )
        score = 0.0
        if check is not None:
            if order not in scores:
                scores[order] = check(grasp)
            value = scores[order]
            if value is None:
                continue
            score = -float(value)
            grasp.quality["check"] = float(value)
        chosen.append((score, order, grasp))
    return chosen


def _contact_arrays(grasp: PlannedGrasp) -> tuple[FloatArray, FloatArray]:
    """A grasp's contact points [m] and outward unit normals, (k, 3) each."""
    return (
        np.array([c.point for c in grasp.contacts]),
        np.array([c.normal for c in grasp.contacts]),
    )


def _wrenches(grasp: PlannedGrasp, frame: ObjectFrame, settings: PlanSettings) -> FloatArray:
    """The primitive wrenches (K, 6) of a grasp's contacts (the plan's friction and cone)."""
    return primitive_wrenches(
        *_contact_arrays(grasp),
        frame.centroid_m,
        frame.radius_m,
        settings.mu,
        settings.cone_edges,
    ).reshape(-1, 6)


def _epsilon_of(grasp: PlannedGrasp, wrenches: FloatArray) -> float:
    """Set and return a grasp's L1 epsilon from its primitive wrenches (:func:`_wrenches`).

    The screening hull (:func:`sahgrasp.quality.wrench.epsilon` with ``exact=False``): within
    about 1e-10 of the exact value.
    """
    value = epsilon(wrenches, exact=False)
    grasp.quality["epsilon_l1"] = value
    grasp.quality["force_closure"] = value > 0.0
    return value


def _epsilon_bound(grasp: PlannedGrasp, frame: ObjectFrame, settings: PlanSettings) -> float:
    """An upper bound of a grasp's L1 epsilon, without the hull (:func:`_support_bound`)."""
    return _support_bound(_wrenches(grasp, frame, settings))


def _support_bound(wrenches: FloatArray) -> float:
    """An upper bound of the L1 epsilon of the primitive ``wrenches`` (K, 6), without the hull.

    For any unit direction ``u``, the ball of radius epsilon inside the hull reaches
    ``epsilon u``, so epsilon is at most the hull's support ``max_i u . w_i``: the smallest
    support over fixed directions (:data:`_BOUND_DIRECTIONS`) bounds it.
    """
    return float((wrenches @ _BOUND_DIRECTIONS.T).max(axis=0).min())


def _directions(count: int) -> FloatArray:
    """The 12 signed axes and ``count`` fixed random unit directions of the wrench space."""
    random = np.random.default_rng(0).normal(size=(count, 6))
    random /= np.linalg.norm(random, axis=1, keepdims=True)
    return np.concatenate([np.eye(6), -np.eye(6), random])


_BOUND_DIRECTIONS = _directions(116)
"""Directions of :func:`_epsilon_bound` (128 in all)."""


def _rank_key(grasp: PlannedGrasp, rank: str) -> tuple[float, float]:
    value = grasp.quality["epsilon_l1" if rank == "epsilon" else rank]
    return (-float(grasp.force_closure), -float(value or 0.0))


def _same(a: PlannedGrasp, b: PlannedGrasp, settings: PlanSettings) -> bool:
    """Same fingers, wrists and every contact within the distinctness thresholds."""
    if a.fingers != b.fingers:
        return False
    if np.linalg.norm(a.q[:3] - b.q[:3]) > settings.distinct_m:
        return False
    dot = abs(float(np.dot(a.q[3:7], b.q[3:7])))
    if 2.0 * math.degrees(math.acos(min(1.0, dot))) > settings.distinct_deg:
        return False
    return all(
        np.linalg.norm(ca.point - cb.point) <= settings.distinct_m
        for ca, cb in zip(a.contacts, b.contacts, strict=True)
    )


def _select(
    hand: Hand,
    verified: list[PlannedGrasp],
    settings: PlanSettings,
    check: GraspCheck | None,
    frame: ObjectFrame,
    scores: dict[int, float | None],
) -> list[PlannedGrasp]:
    """The best distinct grasps (module docstring), with their L-infinity epsilon.

    Ranked by epsilon, the force-closure grasps' epsilons are computed lazily: in the order of
    an upper bound of each (:func:`_epsilon_bound`), until the grasps chosen from those computed
    cannot change -- every grasp not computed has a bound, hence an epsilon, below the last
    chosen one, so it ranks after every chosen grasp. With an extra check, every epsilon is
    computed first: the check is asked about the same grasps, in the same order, as when every
    epsilon is known.
    """
    if settings.rank == "weight":
        missing = [g for g in verified if "weight" not in g.quality]
        contacts = [_contact_arrays(g) for g in missing]
        for grasp, support in zip(
            missing, weight_supports(contacts, frame.centroid_m, settings.mu), strict=True
        ):
            grasp.quality["weight"] = support.support
    if settings.rank != "epsilon":
        chosen = _choose(hand, list(enumerate(verified)), settings, check, frame, scores)
    else:
        for grasp in verified:
            if not grasp.force_closure:
                grasp.quality["epsilon_l1"] = 0.0
        wrenches = {
            i: _wrenches(g, frame, settings) for i, g in enumerate(verified) if g.force_closure
        }
        waiting = sorted((-_support_bound(w), i) for i, w in wrenches.items())
        if check is not None:  # a costly check (physics) is asked once, in the final order
            while waiting:
                i = waiting.pop(0)[1]
                _epsilon_of(verified[i], wrenches[i])
        largest = 0.0  # the largest epsilon computed
        while waiting:
            bound = -waiting[0][0]
            # The chosen grasps are final once the largest bound left is below the least
            # epsilon chosen, itself at most the largest computed: only then are they chosen.
            if bound < largest:
                known = [
                    (i, g) for i, g in enumerate(verified) if g.quality["epsilon_l1"] is not None
                ]
                chosen = _choose(
                    hand, known, settings, check, frame, scores, complete=False, indices=False
                )
                if len(chosen) == settings.grasps:
                    last = min(float(g.quality["epsilon_l1"]) for _, _, g in chosen)
                    if bound < last and all(g.force_closure for _, _, g in chosen):
                        break
            i = waiting.pop(0)[1]
            largest = max(largest, _epsilon_of(verified[i], wrenches[i]))
        known = [(i, g) for i, g in enumerate(verified) if g.quality["epsilon_l1"] is not None]
        chosen = _choose(hand, known, settings, check, frame, scores, complete=not waiting)
    chosen.sort(key=lambda e: (e[0], _rank_key(e[2], settings.rank), e[1]))
    out = []
    for _, _, grasp in chosen:
        # The exact hull for what is returned (the candidates were screened with one that
        # joggles where Qhull meets a precision problem); the L-infinity epsilon where its
        # Minkowski sum is small enough.
        linf = (settings.linf_edges + 1) ** len(grasp.contacts) <= LINF_MAX_POINTS
        exact = grasp_quality(
            *_contact_arrays(grasp),
            frame.centroid_m,
            frame.radius_m,
            settings.mu,
            settings.cone_edges,
            linf=linf,
            linf_edges=settings.linf_edges,
        )
        grasp.quality["force_closure"] = exact.force_closure
        grasp.quality["epsilon_l1"] = exact.epsilon_l1
        grasp.quality["epsilon_linf"] = exact.epsilon_linf
        out.append(grasp)
    return out
