"""Tests of the global grasp optimization of the SAH (Algorithm 1 of the atlas paper)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sahgrasp.errors import AtlasError
from sahgrasp.grasp import GraspSystem
from sahgrasp.hand import Hand
from sahgrasp.objects import can_patches, load_object
from sahgrasp.objects.clearance import HandObjectClearance
from sahgrasp.optimization import GraspOptimizationResult, optimize_grasp, run_experiment
from sahgrasp.viz import Viewer
from sahgrasp.viz.atlas_examples import collision_notes, show_optimization
from sahgrasp.viz.atlas_view import COLLIDING_RGB


@pytest.fixture(scope="module")
def can(sah: Hand) -> GraspOptimizationResult:
    return optimize_grasp(sah, can_patches(), k=2, radius=0.15, obj=load_object("can"))


def test_atlas_of_r_is_complete_and_on_the_manifold(can: GraspOptimizationResult) -> None:
    atlas, system = can.atlas, can.system
    assert atlas.complete and atlas.dim == 2 and atlas.n_charts > 10
    R, _ = can.reduced_system()
    residuals = np.array([np.linalg.norm(R(x)) for x in atlas.centres])
    assert residuals.max() <= 1e-10  # AtlasSettings.newton_tol
    assert (atlas.centres >= system.lower).all() and (atlas.centres <= system.upper).all()
    assert np.array_equal(atlas.centres[0], can.start)
    assert 0.0 < can.retained_variance < 1.0


def test_best_and_worst_are_valid_extremes(can: GraspOptimizationResult) -> None:
    values, valid = can.values, can.valid
    assert valid[can.best] and valid[can.worst]
    assert np.isnan(values[~valid]).all() and np.isfinite(values[valid]).all()
    assert values[can.best] >= values[valid].max()
    assert values[can.worst] <= values[valid].min()
    assert np.array_equal(values[valid], can.all_values[valid])
    assert can.all_values[can.best_overall] == np.max(can.all_values)
    hand = can.system.hand
    for chart in (can.best, can.worst):
        assert not hand.in_collision(can.configurations[chart])


def test_charts_are_checked_against_the_can(can: GraspOptimizationResult) -> None:
    """Valid charts: no self-collision, no link in the can; the free ring finger placed clear."""
    system, hand = can.system, can.system.hand
    assert np.array_equal(can.valid, ~(can.self_collision | can.object_collision))
    assert can.object_collision.any() and can.valid.any()  # phalanges behind the tips touch it
    checker = HandObjectClearance(hand, load_object("can"))
    contacts = ("thumb", "index", "middle")
    ring = [hand.coordinate_index(f"ring_j{j}") for j in (1, 2, 3)]
    for i, x in enumerate(can.atlas.centres):
        q, T = can.configurations[i], system.object_pose(x).homogeneous
        others = np.ones(hand.nq - 7, dtype=bool)
        others[ring] = False
        assert np.array_equal(q[7:][others], system.configuration(x)[7:][others])
        clearance = checker.clearance(q, contacts, T_world_object=T)
        assert clearance.clear() == (not can.object_collision[i])
        ring_links = [clearance.links_m[f"ring_{link}"] for link in ("middle", "distal", "tip")]
        assert min(ring_links) > 0.0  # the free finger touches nothing
    summary = can.summary()
    assert summary["colliding_charts"] == int((~can.valid).sum())
    assert summary["object_collision_charts"] == int(can.object_collision.sum())


def test_summary_is_json(can: GraspOptimizationResult) -> None:
    summary = json.loads(json.dumps(can.summary()))
    assert summary["charts"] == can.atlas.n_charts
    assert (summary["t"], summary["k"], summary["s"]) == (11, 2, 9)
    assert summary["best"]["chart"] == can.best and summary["index"] == "volume"
    assert summary["best"]["value"] >= summary["worst"]["value"]
    assert summary["best"]["collision_free"] and summary["worst"]["collision_free"]
    assert summary["best_overall"]["value"] >= summary["best"]["value"]


def test_user_index(sah: Hand) -> None:
    def spread(system: GraspSystem, x: np.ndarray) -> float:
        return float(x[system.contacts[1].params][0])  # the index finger's angle on the can

    result = optimize_grasp(sah, can_patches(), radius=0.3, index_fn=spread)
    angles = np.array([spread(result.system, x) for x in result.atlas.centres])
    assert np.array_equal(np.isnan(result.values), ~result.valid)
    assert np.allclose(result.values[result.valid], angles[result.valid])
    assert result.best == np.flatnonzero(result.valid)[np.argmax(angles[result.valid])]
    assert result.index == "user" and result.summary()["best"]["singular"] is None


def test_unknown_names_raise(sah: Hand) -> None:
    with pytest.raises(AtlasError, match="unknown index 'dexterity'"):
        optimize_grasp(sah, can_patches(), index="dexterity")
    with pytest.raises(AtlasError, match="unknown experiment"):
        run_experiment("cup")
    with pytest.raises(AtlasError, match="k must"):
        optimize_grasp(sah, can_patches(), k=12, radius=0.3)


def test_bottle_atlas_moves_the_hand() -> None:
    """Without the bottle's spin (a symmetry of every region), R's charts are hand motions."""
    result = run_experiment("bottle", radius=0.1)
    assert result.system.t == 11 and result.atlas.complete
    hand = result.atlas.centres[:, result.system.actuated_rows]
    assert np.ptp(hand, axis=0).max() > 0.1  # rad; with the spin the hand stayed within 0.002


def test_viewer_marks_the_colliding_charts(can: GraspOptimizationResult) -> None:
    with Viewer() as viewer:
        plot = show_optimization(viewer, can)
    purple = np.all(plot.colors_rgb == COLLIDING_RGB, axis=1)
    assert np.array_equal(purple, ~can.valid)
    assert (plot.best, plot.worst) == (can.best, can.worst)
    report = "\n".join(collision_notes(can))
    assert f"{int((~can.valid).sum())} of {can.atlas.n_charts}" in report
    assert f"{int(can.object_collision.sum())} hand-object" in report
