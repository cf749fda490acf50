"""Tests of the weight support (sahgrasp.quality.weight) against hand-computed pinches."""

from __future__ import annotations

import numpy as np
import pytest

from sahgrasp.quality.weight import (
    PULL_DIRECTIONS,
    holds_weight,
    weight_support,
    weight_supports,
)
from sahgrasp.quality.wrench import WrenchError

# A pinch across a sphere of radius 40 mm along x.
PINCH_POINTS = np.array([[0.04, 0.0, 0.0], [-0.04, 0.0, 0.0]])
PINCH_NORMALS = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])


def test_centred_pinch_resists_one_newton_per_newton_in_every_direction() -> None:
    # Along x one finger pushes (N = 1 per unit pull); across, two fingers' friction 2 mu N.
    w = weight_support(PINCH_POINTS, PINCH_NORMALS, np.zeros(3), mu=0.5, patch_radius_m=0.0)
    assert w.support == pytest.approx(1.0, rel=1e-6)
    assert len(w.per_direction) == len(PULL_DIRECTIONS)
    assert all(v == pytest.approx(1.0, rel=1e-6) for v in w.per_direction)


def test_off_centre_pinch_is_limited_by_the_torsional_friction() -> None:
    # The centre of mass 30 mm below the pinch line: a pull along y has a moment 0.03 W about
    # the line, which only the two patches' torsion 2 kappa N resists (kappa = 2/3 mu a); the
    # inner cone approximation shares each finger's N between friction and torsion:
    # W / N = 1 / (1 / (2 mu) + 0.03 / (2 kappa)).
    mu, a = 0.5, 0.0025
    kappa = 2.0 / 3.0 * mu * a
    expected = 1.0 / (1.0 / (2.0 * mu) + 0.03 / (2.0 * kappa))
    w = weight_support(PINCH_POINTS, PINCH_NORMALS, np.array([0.0, 0.0, -0.03]), mu, a)
    assert w.support == pytest.approx(expected, rel=1e-6)
    assert w.weakest in ("+y", "-y")
    # Point contacts: nothing resists that moment.
    hard = weight_support(PINCH_POINTS, PINCH_NORMALS, np.array([0.0, 0.0, -0.03]), mu, 0.0)
    assert hard.support == 0.0


def test_one_sided_contacts_resist_nothing_pulled_away() -> None:
    points = np.array([[0.04, 0.0, 0.0], [0.04, 0.01, 0.0]])
    normals = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    w = weight_support(points, normals, np.zeros(3))
    assert w.support == 0.0
    assert w.per_direction[1] == 0.0  # -x: the fingers, pressing along -x, would have to pull


def test_grasps_solved_together_get_what_each_gets_alone() -> None:
    rng = np.random.default_rng(5)
    sets = []
    for k in (2, 3, 4, 3, 2):
        normals = rng.normal(size=(k, 3))
        normals /= np.linalg.norm(normals, axis=1)[:, None]
        sets.append((0.04 * normals + 0.005 * rng.normal(size=(k, 3)), normals))
    sets.append((PINCH_POINTS[:1], PINCH_NORMALS[:1]))  # one finger: resists no pull at all
    centre = np.array([0.0, 0.002, -0.004])
    together = weight_supports(sets, centre, mu=0.6)
    assert len(together) == len(sets)
    for (points, normals), joint in zip(sets, together, strict=True):
        alone = weight_support(points, normals, centre, mu=0.6)
        assert joint.weakest == alone.weakest
        assert joint.per_direction == pytest.approx(alone.per_direction, abs=1e-12)
    assert together[-1].support == 0.0
    assert weight_supports([], centre) == []


def test_support_is_invariant_to_a_rigid_motion_of_pinch_and_centre_about_z() -> None:
    rotation = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
    centre = np.array([0.0, 0.0, -0.01])
    a = weight_support(PINCH_POINTS, PINCH_NORMALS, centre)
    b = weight_support(PINCH_POINTS @ rotation.T, PINCH_NORMALS @ rotation.T, centre)
    assert b.support == pytest.approx(a.support, rel=1e-6)


def test_holds_weight_compares_the_weight_with_the_support_times_the_squeeze() -> None:
    assert holds_weight(0.1, mass_kg=0.1, squeeze_n=10.0)  # 0.981 N <= 1 N
    assert not holds_weight(0.1, mass_kg=0.11, squeeze_n=10.0)  # 1.079 N > 1 N
    with pytest.raises(WrenchError, match="mass_kg"):
        holds_weight(0.1, mass_kg=0.0, squeeze_n=10.0)


@pytest.mark.parametrize(
    ("points", "normals", "centre", "match"),
    [
        (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(3), "non-empty"),
        (PINCH_POINTS, PINCH_NORMALS[:1], np.zeros(3), "match"),
        (PINCH_POINTS, PINCH_NORMALS, np.zeros(2), "centre of mass"),
        (PINCH_POINTS, 2.0 * PINCH_NORMALS, np.zeros(3), "unit"),
        (PINCH_POINTS * np.nan, PINCH_NORMALS, np.zeros(3), "finite"),
    ],
)
def test_malformed_inputs_raise(
    points: np.ndarray, normals: np.ndarray, centre: np.ndarray, match: str
) -> None:
    with pytest.raises(WrenchError, match=match):
        weight_support(points, normals, centre)


def test_bad_friction_and_patch_radius_raise() -> None:
    with pytest.raises(WrenchError, match="friction"):
        weight_support(PINCH_POINTS, PINCH_NORMALS, np.zeros(3), mu=-1.0)
    with pytest.raises(WrenchError, match="patch_radius_m"):
        weight_support(PINCH_POINTS, PINCH_NORMALS, np.zeros(3), patch_radius_m=-0.001)


def test_the_planner_ranks_by_the_weight_support(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import trimesh

    from sahgrasp.model.hand import load_hand
    from sahgrasp.objects import load_mesh
    from sahgrasp.planner import PlanSettings, plan_grasps
    from sahgrasp.planner.candidates import ObjectFrame

    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=(0.05, 0.07, 0.09)).export(path)
    obj = load_mesh(path)
    settings = PlanSettings(candidates=8, grasps=4, seed=4, rank="weight")
    plan = plan_grasps(load_hand("sah"), obj, settings)
    assert plan.grasps
    mesh = obj.mesh()
    centre = ObjectFrame.of(mesh.vertices_m, mesh.faces).centroid_m
    for closure in (True, False):
        values = [g.quality["weight"] for g in plan.grasps if g.force_closure == closure]
        assert values == sorted(values, reverse=True)
    for g in plan.grasps:
        points = np.array([c.point for c in g.contacts])
        normals = np.array([c.normal for c in g.contacts])
        expected = weight_support(points, normals, centre, settings.mu).support
        # The planner scores the contact targets; the returned contacts are those targets.
        assert g.quality["weight"] == pytest.approx(expected, rel=1e-6, abs=1e-9)
