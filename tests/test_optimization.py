"""Tests of the global grasp optimization of the SAH (Algorithm 1 of the atlas paper)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.core.errors import GraspSystemError, OptimizationError, QualityError
from sahgrasp.experiments.atlas_examples import show_optimization
from sahgrasp.experiments.report import collision_notes, summary
from sahgrasp.experiments.setups import run_experiment
from sahgrasp.model.hand import Hand
from sahgrasp.objects import can_patches, load_object
from sahgrasp.optimization.grasp import (
    HandGraspManifold,
    coordinate_scales,
    ik_seeds,
    make_sah_manifold,
)
from sahgrasp.optimization.optimizer import (
    ChartChecks,
    OptimizationResult,
    OptimizationSettings,
    optimize,
    optimize_components,
)
from sahgrasp.quality.ellipsoids import Manipulability
from sahgrasp.viz import Viewer
from sahgrasp.viz.atlas_view import COLLIDING_RGB

SAH = OptimizationSettings(radius=0.15, epsilon=0.5)


@pytest.fixture(scope="module")
def can_problem(sah: Hand) -> HandGraspManifold:
    return make_sah_manifold(sah, can_patches(), k=2, obj=load_object("can"))


@pytest.fixture(scope="module")
def can(can_problem: HandGraspManifold) -> OptimizationResult:
    return optimize(can_problem, SAH)


def sah_problem(result: OptimizationResult) -> HandGraspManifold:
    assert isinstance(result.problem, HandGraspManifold)
    return result.problem


def test_atlas_of_r_is_complete_and_on_the_manifold(can: OptimizationResult) -> None:
    problem = sah_problem(can)
    atlas, system = can.atlas, problem.system
    assert atlas.complete and atlas.dim == 2 and atlas.n_charts > 10
    residuals = np.array([np.linalg.norm(problem.F(x)) for x in atlas.centres])
    assert residuals.max() <= 1e-10  # AtlasSettings.newton_tol
    assert (atlas.centres >= system.lower).all() and (atlas.centres <= system.upper).all()
    assert np.array_equal(atlas.centres[0], problem.start)
    assert 0.0 < problem.retained_variance < 1.0


def test_best_and_worst_are_valid_extremes(can: OptimizationResult) -> None:
    values, valid = can.values, can.valid
    assert valid[can.best] and valid[can.worst]
    assert np.isnan(values[~valid]).all() and np.isfinite(values[valid]).all()
    assert values[can.best] >= values[valid].max()
    assert values[can.worst] <= values[valid].min()
    assert np.array_equal(values[valid], can.all_values[valid])
    assert can.all_values[can.best_overall] == np.max(can.all_values)
    hand = sah_problem(can).system.hand
    for chart in (can.best, can.worst):
        assert not hand.in_collision(can.configurations[chart])


def test_charts_are_checked_against_the_can(can: OptimizationResult) -> None:
    """Valid charts: no self-collision, no link in the can; the free ring finger placed clear."""
    system = sah_problem(can).system
    hand, checks = system.hand, can.checks
    assert np.array_equal(can.valid, ~(checks.self_collision | checks.object_collision))
    assert checks.object_collision.any() and can.valid.any()  # phalanges behind the tips
    checker = HandObjectClearance(hand, load_object("can"))
    contacts = ("thumb", "index", "middle")
    ring = [hand.coordinate_index(f"ring_j{j}") for j in (1, 2, 3)]
    for i, x in enumerate(can.atlas.centres):
        q, T = can.configurations[i], system.object_pose(x).homogeneous
        others = np.ones(hand.nq - 7, dtype=bool)
        others[ring] = False
        assert np.array_equal(q[7:][others], system.configuration(x)[7:][others])
        clearance = checker.clearance(q, contacts, T_world_object=T)
        assert clearance.clear() == (not checks.object_collision[i])
        ring_links = [clearance.links_m[f"ring_{link}"] for link in ("middle", "distal", "tip")]
        assert min(ring_links) > 0.0  # the free finger touches nothing
    out = summary("can", can)
    assert out["colliding_charts"] == int((~can.valid).sum())
    assert out["object_collision_charts"] == int(checks.object_collision.sum())


def test_summary_is_json(can: OptimizationResult) -> None:
    out = json.loads(json.dumps(summary("can", can)))
    assert out["charts"] == can.atlas.n_charts
    assert (out["t"], out["k"], out["s"]) == (11, 2, 9)
    assert out["best"]["chart"] == can.best and out["index"] == "volume"
    assert out["best"]["value"] >= out["worst"]["value"]
    assert out["best"]["collision_free"] and out["worst"]["collision_free"]
    assert out["best_overall"]["value"] >= out["best"]["value"]
    assert 0.0 < out["retained_variance"] < 1.0
    assert out["indices"]["volume"]["best"]["chart"] == can.best


def test_user_index(can_problem: HandGraspManifold) -> None:
    column = can_problem.system.contacts[1].params.start  # the index finger's angle on the can

    def spread(centres: np.ndarray) -> np.ndarray:
        return centres[:, column]

    settings = OptimizationSettings(radius=0.3, epsilon=0.5, index_fn=spread)
    result = optimize(can_problem, settings)
    angles = result.atlas.centres[:, column]
    assert np.array_equal(np.isnan(result.values), ~result.valid)
    assert np.allclose(result.values[result.valid], angles[result.valid])
    assert result.best == np.flatnonzero(result.valid)[np.argmax(angles[result.valid])]
    assert result.index == "user" and result.quality is None
    assert summary("can", result)["best"]["singular"] is None
    with pytest.raises(OptimizationError, match="user index_fn"):
        result.ranked_by("volume")
    with pytest.raises(QualityError, match="values for"):
        optimize(can_problem, OptimizationSettings(0.3, 0.5, index_fn=lambda X: X[:1, 0]))


def test_unknown_names_raise(sah: Hand, can_problem: HandGraspManifold) -> None:
    with pytest.raises(OptimizationError, match="unknown index 'dexterity'"):
        OptimizationSettings(radius=0.1, epsilon=0.5, index="dexterity")
    with pytest.raises(OptimizationError, match="unknown experiment 'cup'; valid: planar, can"):
        run_experiment("cup")
    with pytest.raises(GraspSystemError, match="k must"):
        HandGraspManifold(can_problem.system, can_problem.motions, 12, can_problem.start)


def test_bottle_atlas_moves_the_hand() -> None:
    """Without the bottle's spin (a symmetry of every region), R's charts are hand motions."""
    result = run_experiment("bottle", radius=0.1)
    system = sah_problem(result).system
    assert system.t == 11 and result.atlas.complete
    hand = result.atlas.centres[:, system.actuated_rows]
    assert np.ptp(hand, axis=0).max() > 0.1  # rad; with the spin the hand stayed within 0.002


def test_viewer_marks_the_colliding_charts(can: OptimizationResult) -> None:
    with Viewer() as viewer:
        plot = show_optimization(viewer, can)
    purple = np.all(plot.colors_rgb == COLLIDING_RGB, axis=1)
    assert np.array_equal(purple, ~can.valid)
    assert (plot.best, plot.worst) == (can.best, can.worst)
    report = "\n".join(collision_notes(can))
    assert f"{int((~can.valid).sum())} of {can.atlas.n_charts}" in report
    assert f"{int(can.checks.object_collision.sum())} hand-object" in report


class TwoLines:
    """R = the lines x0 = -1 and x0 = 1 of the plane, x1 in [-1, 1]: two components."""

    dimension, t = 1, 1
    start = np.array([1.0, 0.0])

    def F(self, x: np.ndarray) -> np.ndarray:
        return np.array([x[0] ** 2 - 1.0])

    def J(self, x: np.ndarray) -> np.ndarray:
        return np.array([[2.0 * x[0], 0.0]])

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return np.array([-2.0, -1.0]), np.array([2.0, 1.0])

    def manipulability(self, x: np.ndarray) -> Manipulability:
        raise AssertionError("a user index needs no ellipsoid")

    def check_charts(self, centres: np.ndarray) -> ChartChecks:
        return ChartChecks.none(centres)


def test_one_atlas_per_component_met_by_the_seeds() -> None:
    settings = OptimizationSettings(radius=0.1, epsilon=0.5, index_fn=lambda X: X[:, 0] + X[:, 1])
    seeds = [[1.1, 0.0], [-0.9, 0.5], [0.95, 0.8], [1.0, 5.0], [-1.0, -0.9]]
    search = optimize_components(TwoLines(), settings, seeds)
    assert search.seed_components == (0, 1, 0, None, 1)  # [1, 5] is out of bounds
    right, left = search.components
    assert np.allclose(right.atlas.centres[:, 0], 1.0) and np.allclose(
        left.atlas.centres[:, 0], -1.0
    )
    assert search.best == (0, right.best)
    assert right.atlas.centres[right.best, 1] == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(OptimizationError, match="none of the 1 seeds"):
        optimize_components(TwoLines(), settings, [[0.0, 5.0]])
    with pytest.raises(OptimizationError, match="seeds must be"):
        optimize_components(TwoLines(), settings, [1.0, 0.0])


def test_ik_seeds_of_the_can_fall_in_the_first_grasps_component(
    can_problem: HandGraspManifold, can: OptimizationResult
) -> None:
    system = can_problem.system
    assert np.allclose(system.point(system.q_first), system.x_first)
    seeds = ik_seeds(can_problem, 3)
    assert np.array_equal(seeds[0], can_problem.start) and seeds.shape[1] == system.n
    search = optimize_components(can_problem, SAH, seeds)
    assert search.seed_components[0] == 0
    first = search.components[0]
    assert first.atlas.n_charts == can.atlas.n_charts and first.best == can.best
    assert all(c in (0, None) for c in search.seed_components)  # those reaching R: x_1's


def test_scaled_coordinates_cover_the_same_grasps(
    can_problem: HandGraspManifold, can: OptimizationResult
) -> None:
    system = can_problem.system
    scales = coordinate_scales(system, 0.1)
    scaled = HandGraspManifold(system, can_problem.motions, 2, can_problem.x_of(can_problem.start),
                              can_problem.obj, scales)  # fmt: skip
    assert np.allclose(scaled.x_of(scaled.start), can_problem.start)
    result = optimize(scaled, SAH)
    x = scaled.x_of(result.atlas.centres)
    assert np.abs([can_problem.F(p) for p in x]).max() <= 1e-8  # on R, in x
    assert np.all((x >= system.lower - 1e-12) & (x <= system.upper + 1e-12))
    assert result.all_values[result.best] == pytest.approx(can.all_values[can.best], rel=0.1)
    with pytest.raises(GraspSystemError, match="scales must be"):
        HandGraspManifold(system, can_problem.motions, 2, can_problem.start, scales=-scales)


def test_the_old_manifold_name_warns_and_is_the_new_class() -> None:
    import sahgrasp.optimization.grasp as grasp

    with pytest.warns(DeprecationWarning, match="SahGraspManifold is deprecated"):
        old = grasp.SahGraspManifold
    assert old is HandGraspManifold
