"""Global grasp optimization (atlas-grasp-optimization, Algorithm 1) on a sahgrasp hand.

``GraspOptimization(F, X_h, x_1, Q, t, k, r, epsilon)``: principal hand motions from sampled hand
configurations, ``R = F + E_s^T (x_h - x_1h)`` with ``s = t - k``, an atlas of ``R`` from the first
grasp (found with the IK), and a quality index at every chart centre. The fingertip contact regions
are box bounds of the atlas.

Collisions (Section IV: "collisions could be considered as well ... returning the best collision
free grasp"): at every chart centre scored, the fingers without a contact region are first placed
where they touch nothing (``HandObjectClearance.place_free_fingers``: the nearest configuration of
their own joints clear of the object and of the other links; they are no part of F, so this
changes neither the grasp nor its index), then the hand is checked for self-collision and, given
the object, for hand-object collision (any link inside the object, the contact fingertip spheres
excepted up to ``d_min``). Colliding chart centres are no candidates: the optimum returned is the
best collision-free grasp, and the best over all charts is kept beside it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas import Atlas, AtlasSettings, build_atlas
from sahgrasp.errors import AtlasError
from sahgrasp.grasp import GraspSystem, reduced_system
from sahgrasp.hand import Hand, load_hand
from sahgrasp.ik import solve_ik
from sahgrasp.motions import PrincipalMotions, principal_motions
from sahgrasp.objects import GraspObject, GraspPatches, bottle_patches, can_patches, load_object
from sahgrasp.objects.clearance import HandObjectClearance
from sahgrasp.quality import (
    INDICES,
    SINGULAR_THRESHOLDS,
    Manipulability,
    ellipsoid_indices,
    null_space,
)

__all__ = [
    "EXPERIMENTS",
    "Experiment",
    "GraspOptimizationResult",
    "first_grasp_system",
    "free_fingers",
    "hand_motions",
    "optimize_grasp",
    "run_experiment",
]


@dataclass(frozen=True)
class GraspOptimizationResult:
    """Outcome of :func:`optimize_grasp`.

    Attributes:
        system: The feasible-grasp system F.
        atlas: The atlas of R.
        index: Name of the quality index (``"user"`` for a user ``index_fn``).
        values: Index per chart (NaN where the chart centre is not a valid grasp).
        valid: Chart centres without collision (self and hand-object).
        best: Chart with the largest index among valid ones.
        worst: Chart with the smallest index among valid ones.
        all_values: Index per chart, colliding charts included.
        best_overall: Chart with the largest index over all charts (``best`` if that is valid).
        configurations: Hand configuration per chart (palm at the origin), free fingers placed.
        self_collision: Chart centres where the hand collides with itself.
        object_collision: Chart centres where a link is inside the object (all False without
            an object).
        obj: The object (in its own frame), or None when only self-collision is checked.
        retained_variance: Share of the hand-motion variance the kept motions explain.
        atlas_seconds: Atlas build time [s].
        quality_seconds: Index evaluation time (with the validity checks) [s].
        motions: The principal hand motions (Section III).
        start: The first grasp ``x_1`` the atlas starts from and Eq. (13) passes through.
        settings: The atlas settings.
    """

    system: GraspSystem
    atlas: Atlas
    index: str
    values: NDArray[np.float64]
    valid: NDArray[np.bool_]
    best: int
    worst: int
    retained_variance: float
    atlas_seconds: float
    quality_seconds: float
    motions: PrincipalMotions
    start: NDArray[np.float64]
    settings: AtlasSettings
    all_values: NDArray[np.float64]
    best_overall: int
    configurations: NDArray[np.float64]
    self_collision: NDArray[np.bool_]
    object_collision: NDArray[np.bool_]
    obj: GraspObject | None

    def reduced_system(self) -> tuple[Any, Any]:
        """``R`` and its Jacobian (Eq. (11)) whose solution set the atlas covers."""
        return reduced_system(self.system, self.motions, self.atlas.dim, self.start)

    def summary(self) -> dict[str, Any]:
        """JSON-able summary (charts, dimensions, times, best and worst grasps)."""

        def grasp(i: int) -> dict[str, Any]:
            threshold = SINGULAR_THRESHOLDS.get(self.index)
            value = float(self.all_values[i])
            return {"chart": i, "value": value,
                    "singular": None if threshold is None else bool(value < threshold),
                    "collision_free": bool(self.valid[i]),
                    "joints": self.system.hand.joint_values(self.configurations[i]),
                    "x": self.atlas.centres[i].tolist()}  # fmt: skip

        return {
            "problem": self.system.patches.name,
            "charts": self.atlas.n_charts,
            "complete": self.atlas.complete,
            "n": self.system.n,
            "t": self.system.t,
            "k": self.atlas.dim,
            "s": self.system.t - self.atlas.dim,
            "r": self.atlas.radius,
            "epsilon": self.atlas.epsilon,
            "index": self.index,
            "valid_charts": int(self.valid.sum()),
            "colliding_charts": int((~self.valid).sum()),
            "self_collision_charts": int(self.self_collision.sum()),
            "object_collision_charts": int(self.object_collision.sum()),
            "retained_variance": self.retained_variance,
            "atlas_seconds": self.atlas_seconds,
            "quality_seconds": self.quality_seconds,
            "best": grasp(self.best),
            "worst": grasp(self.worst),
            "best_overall": grasp(self.best_overall),
        }


def hand_motions(hand: Hand, system: GraspSystem, samples: int, seed: int) -> PrincipalMotions:
    """PCA of collision-free random hand configurations, restricted to ``x_h`` (Section III)."""
    rng = np.random.default_rng(seed)
    X = np.array([hand.random_configuration(rng, collision_free=True)[7:] for _ in range(samples)])
    return principal_motions(X[:, system.coordinates])


def free_fingers(hand: Hand, patches: GraspPatches) -> tuple[str, ...]:
    """The fingers without a contact region: no part of F, placed clear of everything."""
    return tuple(f for f in hand.fingers if f not in patches.regions)


def first_grasp_system(
    hand: Hand,
    patches: GraspPatches,
    free_object: bool = True,
    symmetry_axis: ArrayLike | None = None,
    obj: GraspObject | None = None,
) -> GraspSystem:
    """F for ``hand`` and ``patches`` around the IK's grasp at the regions' nominal parameters.

    Fingers without a contact region are left free (they do not enter ``x``); given the object
    (in the regions' frame), they are placed clear of it and of the other links
    (``HandObjectClearance.place_free_fingers``). ``free_object`` and ``symmetry_axis`` are those
    of :class:`~sahgrasp.grasp.GraspSystem`.

    Raises:
        AtlasError: The IK finds no such grasp.
    """
    free = free_fingers(hand, patches)
    first = solve_ik(hand, patches.target(), free_fingers=free)
    if not first.success:
        raise AtlasError(f"{patches.name}: the IK found no first grasp ({first.reason})")
    q = first.q
    if obj is not None and free:  # the IK's world is the object frame
        q = HandObjectClearance(hand, obj.placed(np.eye(4))).place_free_fingers(q, free).q
    return GraspSystem(hand, patches, q, free_object, symmetry_axis)


def optimize_grasp(
    hand: Hand,
    patches: GraspPatches,
    k: int = 2,
    radius: float = 0.1,
    epsilon: float = 0.5,
    index: str = "volume",
    free_object: bool = True,
    symmetry_axis: ArrayLike | None = None,
    max_charts: int = 20_000,
    motion_samples: int = 2000,
    seed: int = 0,
    progress: bool = False,
    index_fn: Callable[[GraspSystem, NDArray[np.float64]], float] | None = None,
    obj: GraspObject | None = None,
) -> GraspOptimizationResult:
    """Algorithm 1 of the atlas paper for ``hand`` and the object's contact ``patches``.

    Args:
        hand: The hand.
        patches: Contact regions per finger in the object frame (fingers without one are free).
        k: Dimension of the relevant-grasp set R.
        radius: Chart radius ``r`` (x mixes radians and metres; see docs/atlas.md).
        epsilon: Threshold of Eqs. (17)-(18).
        index: Manipulability index (``inverse_condition``, ``volume``, ``min_semiaxis``).
        free_object: Let the object pose vary (else it is fixed in the palm).
        symmetry_axis: Axis (object frame) about which every contact region is revolved: the
            object's spin about it, which changes nothing but the parametrisation, is left out.
        max_charts: Cap on the atlas size.
        motion_samples: Hand configurations sampled for the principal motions.
        seed: Seed of those samples.
        progress: Show the atlas progress bar.
        index_fn: A user quality index ``f(system, x) -> float`` instead of ``index``; larger
            is better.
        obj: The object, in the frame of ``patches``: chart centres where a link is inside it
            (contact fingertips excepted up to ``d_min``) are no candidates, and the free
            fingers are placed clear of it. None: only self-collision is checked.

    Raises:
        AtlasError: ``index`` is unknown (and no ``index_fn`` given), the IK finds no first grasp,
            ``k`` is not in ``[1, t]``, or no chart centre is collision-free.
    """
    if index_fn is None and index not in INDICES:
        raise AtlasError(f"unknown index {index!r}; valid: {list(INDICES)} or a callable")
    system = first_grasp_system(hand, patches, free_object, symmetry_axis, obj)
    motions = hand_motions(hand, system, motion_samples, seed)
    x1 = _start_inside(system.F, system.J, system.x_first, system.lower, system.upper)
    R, JR = reduced_system(system, motions, k, x1)
    settings = AtlasSettings(radius=radius, epsilon=epsilon, max_charts=max_charts,
                             start_tol=1e-4, progress=progress)  # fmt: skip
    start = time.perf_counter()
    atlas = build_atlas(R, JR, x1, k, settings, system.lower, system.upper)
    atlas_seconds = time.perf_counter() - start
    start = time.perf_counter()
    checks = _check_charts(system, atlas, obj)
    values = _evaluate(system, atlas, index, index_fn)
    quality_seconds = time.perf_counter() - start
    valid = ~(checks.self_collision | checks.object_collision)
    candidates = np.flatnonzero(valid)
    if not candidates.size:
        raise AtlasError(
            f"{patches.name}: no chart centre is a collision-free grasp "
            f"({int(checks.self_collision.sum())} of {atlas.n_charts} self-colliding, "
            f"{int(checks.object_collision.sum())} inside the object)"
        )
    best = int(candidates[np.argmax(values[candidates])])
    worst = int(candidates[np.argmin(values[candidates])])
    return GraspOptimizationResult(
        system, atlas, "user" if index_fn else index, np.where(valid, values, np.nan), valid,
        best, worst, motions.retained_variance(system.t - k), atlas_seconds, quality_seconds,
        motions, x1, settings, values, int(np.argmax(values)), checks.configurations,
        checks.self_collision, checks.object_collision, obj,
    )  # fmt: skip


def _start_inside(
    F: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    J: Callable[[NDArray[np.float64]], NDArray[np.float64]],
    x: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    margin: float = 1e-4,
) -> NDArray[np.float64]:
    """The first grasp moved ``margin`` inside the box and back onto ``F = 0``.

    The IK leaves joints exactly at their limits, where the atlas's projection could step out of
    the box; coordinates moved inside stay fixed while Newton corrects the others, until all are
    inside.
    """
    inside = x.copy()
    free = np.ones(x.size, dtype=bool)
    for _ in range(10):
        clipped = np.clip(inside, lower + margin, upper - margin)
        free &= clipped == inside
        inside = clipped
        for _ in range(20):
            residual = F(inside)
            if np.linalg.norm(residual) < 1e-12:
                break
            inside[free] += np.linalg.lstsq(J(inside)[:, free], -residual, rcond=None)[0]
        if np.all((inside >= lower + margin) & (inside <= upper - margin)):
            return inside
    raise AtlasError("the first grasp cannot be moved inside the joint and region bounds")


def _manipulability(system: GraspSystem, x: NDArray[np.float64]) -> Manipulability:
    """Ellipsoid of object twists reachable with unit actuated joint velocity (hard fingers)."""
    C = system.hard_finger_constraints(x)
    a = len(system.actuated_rows)
    motions = null_space(C, C.shape[1] - C.shape[0])
    return ellipsoid_indices(motions[:a], motions[a:])


@dataclass(frozen=True)
class _ChartChecks:
    """Per chart centre: the hand configuration (free fingers placed) and its collisions."""

    configurations: NDArray[np.float64]
    self_collision: NDArray[np.bool_]
    object_collision: NDArray[np.bool_]


def _check_charts(system: GraspSystem, atlas: Atlas, obj: GraspObject | None) -> _ChartChecks:
    """Place the free fingers at every chart centre, then check self- and object collision."""
    hand = system.hand
    configurations = np.array([system.configuration(x) for x in atlas.centres])
    object_collision = np.zeros(atlas.n_charts, dtype=bool)
    if obj is not None:
        checker = HandObjectClearance(hand, obj)
        free = free_fingers(hand, system.patches)
        contacts = [c.finger for c in system.contacts]
        for i, x in enumerate(atlas.centres):
            T = system.object_pose(x).homogeneous  # palm at the origin: palm frame = world
            if free:
                configurations[i] = checker.place_free_fingers(configurations[i], free,
                                                               T_world_object=T).q  # fmt: skip
            clearance = checker.clearance(configurations[i], contacts, T_world_object=T)
            object_collision[i] = not clearance.clear()
    self_collision = np.array([hand.in_collision(q) for q in configurations], dtype=bool)
    return _ChartChecks(configurations, self_collision, object_collision)


def _evaluate(
    system: GraspSystem,
    atlas: Atlas,
    index: str,
    index_fn: Callable[[GraspSystem, NDArray[np.float64]], float] | None,
) -> NDArray[np.float64]:
    """The quality index at every chart centre (the free fingers do not enter it)."""
    if index_fn is not None:
        return np.array([index_fn(system, x) for x in atlas.centres], dtype=np.float64)
    return np.array([_manipulability(system, x).index(index) for x in atlas.centres])


@dataclass(frozen=True)
class Experiment:
    """One of the atlas paper's SAH experiments (Section V).

    Attributes:
        patches: Builds the object's contact regions.
        object: Builds the object, in the regions' frame.
        free_object: Whether the object pose varies.
        symmetry_axis: Axis of revolution shared by every contact region (object frame), if any.
    """

    patches: Callable[[], GraspPatches]
    object: Callable[[], GraspObject]
    free_object: bool = True
    symmetry_axis: tuple[float, float, float] | None = None


EXPERIMENTS = {
    # The thumb's fixed point breaks the can's symmetry.
    "can": Experiment(can_patches, lambda: load_object("can")),
    "bottle": Experiment(
        bottle_patches, lambda: load_object("bottle"), symmetry_axis=(0.0, 0.0, 1.0)
    ),
}
"""The SAH + can (Fig. 10a) and SAH + oil bottle (Fig. 10b) experiments, by name."""


def run_experiment(
    name: str, hand: str = "sah", k: int = 2, radius: float = 0.1, epsilon: float = 0.5,
    index: str = "volume", max_charts: int = 20_000, progress: bool = False,
) -> GraspOptimizationResult:  # fmt: skip
    """Run the SAH + can or SAH + oil bottle experiment of Section V (object collisions checked)."""
    if name not in EXPERIMENTS:
        raise AtlasError(f"unknown experiment {name!r}; valid: {sorted(EXPERIMENTS)}")
    experiment = EXPERIMENTS[name]
    return optimize_grasp(
        load_hand(hand), experiment.patches(), k=k, radius=radius, epsilon=epsilon, index=index,
        free_object=experiment.free_object, symmetry_axis=experiment.symmetry_axis,
        max_charts=max_charts, progress=progress, obj=experiment.object(),
    )  # fmt: skip
