"""Force closure and Ferrari-Canny epsilon against hand-computed cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sahgrasp.quality.wrench import (
    WrenchError,
    cone_edges,
    epsilon,
    force_closure,
    grasp_quality,
    primitive_wrenches,
)

MU = 0.5


def test_antipodal_pinch_on_a_sphere_is_not_force_closure() -> None:
    # Two hard fingers on the poles of a unit sphere: every wrench has zero torque about the
    # z axis (r x f with r along z has no z component), so the wrenches span five dimensions:
    # no ball about the origin fits, whatever the friction.
    points = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]
    for mu in (0.2, 0.5, 2.0):
        w = primitive_wrenches(points, points, [0.0, 0.0, 0.0], 1.0, mu)
        assert np.allclose(w[..., 5], 0.0)
        q = grasp_quality(points, points, [0.0, 0.0, 0.0], 1.0, mu)
        assert not q.force_closure
        assert q.epsilon_l1 == 0.0 and q.epsilon_linf == 0.0


def _cube_wrenches(mu: float) -> np.ndarray:
    """By hand: contacts at the centres of the +x, -x and +y faces of the cube [-1, 1]^3.

    Edge forces of a 4-edge pyramid (normal component 1, tangential mu along the face axes),
    torques r x f with the centre at the origin and radius 1.
    """
    rows = []
    # +x face, r = (1, 0, 0): tau = (0, -fz, fy)
    for f in ((-1, 0, mu), (-1, 0, -mu), (-1, mu, 0), (-1, -mu, 0)):
        rows.append((*f, 0.0, -f[2], f[1]))
    # -x face, r = (-1, 0, 0): tau = (0, fz, -fy)
    for f in ((1, 0, mu), (1, 0, -mu), (1, mu, 0), (1, -mu, 0)):
        rows.append((*f, 0.0, f[2], -f[1]))
    # +y face, r = (0, 1, 0): tau = (fz, 0, -fx)
    for f in ((0, -1, mu), (0, -1, -mu), (mu, -1, 0), (-mu, -1, 0)):
        rows.append((*f, f[2], 0.0, -f[0]))
    return np.array(rows, dtype=np.float64)


def test_three_finger_cube_grasp_matches_the_hand_computed_epsilon() -> None:
    points = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    w = primitive_wrenches(points, points, [0.0, 0.0, 0.0], 1.0, MU, edges=4).reshape(-1, 6)
    expected = _cube_wrenches(MU)
    # The same 12 wrenches (the pyramid's edge order is the module's).
    assert sorted(map(tuple, np.round(w, 12))) == sorted(map(tuple, np.round(expected, 12)))
    # The nearest facet, by hand: u = (1, 2, 2, -8, -2, 2) / 9 (a unit vector: 81 = 9^2).
    # u . w = (-1 + 4 mu) / 9 = 1/9 for the +x wrenches (-1, 0, mu, 0, -mu, 0) and
    # (-1, mu, 0, 0, 0, mu), the -x wrenches (1, 0, -mu, 0, -mu, 0), (1, -mu, 0, 0, 0, mu),
    # (1, 0, mu, 0, mu, 0), (1, mu, 0, 0, 0, -mu) and the +y wrench (0, -1, -mu, -mu, 0, 0);
    # every other wrench is below: the hull has a facet at distance 1/9 from the origin.
    u = np.array([1.0, 2.0, 2.0, -8.0, -2.0, 2.0]) / 9.0
    support = expected @ u
    assert support.max() == pytest.approx(1.0 / 9.0)
    assert np.sum(np.isclose(support, 1.0 / 9.0)) >= 6
    q = grasp_quality(points, points, [0.0, 0.0, 0.0], 1.0, MU, edges=4, linf_edges=4)
    assert q.force_closure
    assert q.epsilon_l1 == pytest.approx(1.0 / 9.0, abs=1e-12)
    # W_1 lies inside W_inf (each contact may push less than 1): never a smaller epsilon.
    assert q.epsilon_linf is not None and q.epsilon_linf >= q.epsilon_l1


def test_epsilon_scales_with_the_torque_radius_and_the_object_size() -> None:
    points = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    # The same grasp of a cube twice as large, with the radius doubled: the same quality.
    a = grasp_quality(points, points, [0.0, 0.0, 0.0], math.sqrt(3.0), linf=False)
    b = grasp_quality(2.0 * points, points, [0.0, 0.0, 0.0], 2.0 * math.sqrt(3.0), linf=False)
    assert a.epsilon_l1 == pytest.approx(b.epsilon_l1, rel=1e-9)


def test_more_friction_is_never_worse() -> None:
    points = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    values = [
        grasp_quality(points, points, [0, 0, 0], 1.0, mu, linf=False).epsilon_l1
        for mu in (0.2, 0.5, 1.0)
    ]
    assert values[0] <= values[1] <= values[2]


def test_cone_edges_have_unit_normal_component_and_friction_slope() -> None:
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.6, 0.8, 0.0]])
    edges = cone_edges(normals, 0.3, 8)
    along = np.einsum("ckj,cj->ck", edges, -normals)
    assert np.allclose(along, 1.0)
    tangential = edges + normals[:, None, :]
    assert np.allclose(np.linalg.norm(tangential, axis=2), 0.3)


def test_flat_and_degenerate_wrench_sets_are_not_force_closure() -> None:
    assert epsilon(np.zeros((10, 6))) == 0.0
    assert epsilon(np.random.default_rng(0).normal(size=(5, 6))) == 0.0
    flat = np.random.default_rng(1).normal(size=(40, 6))
    flat[:, 4] = 0.0
    assert epsilon(flat) == 0.0
    shifted = np.random.default_rng(2).normal(size=(40, 6)) + 10.0  # origin outside
    assert epsilon(shifted) == 0.0


@pytest.mark.parametrize(
    ("points", "normals", "match"),
    [
        ([[0, 0, 0]], [[0, 0, 2]], "unit"),
        ([[0, 0, 0]], [[0, 0]], "shape"),
        ([[np.nan, 0, 0]], [[0, 0, 1]], "finite"),
    ],
)
def test_malformed_contacts_are_refused(points, normals, match) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(WrenchError, match=match):
        grasp_quality(points, normals, [0, 0, 0], 1.0)


def test_bad_parameters_are_refused() -> None:
    p = [[0.0, 0.0, 1.0]]
    with pytest.raises(WrenchError, match="friction"):
        grasp_quality(p, p, [0, 0, 0], 1.0, mu=-1.0)
    with pytest.raises(WrenchError, match="edges"):
        grasp_quality(p, p, [0, 0, 0], 1.0, edges=2)
    with pytest.raises(WrenchError, match="radius"):
        grasp_quality(p, p, [0, 0, 0], 0.0)


def test_force_closure_without_the_hull_agrees_with_the_hull() -> None:
    # The hand-computed cases: the antipodal pinch (flat) is not, the cube grasp is.
    poles = [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]
    assert not force_closure(primitive_wrenches(poles, poles, [0, 0, 0], 1.0, MU).reshape(-1, 6))
    cube = np.array([[1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    assert force_closure(primitive_wrenches(cube, cube, [0, 0, 0], 1.0, MU).reshape(-1, 6))
    # Without friction the cube's three contacts hold nothing along -y: not force closure.
    assert not force_closure(primitive_wrenches(cube, cube, [0, 0, 0], 1.0, 0.0).reshape(-1, 6))
    # Random 3- and 4-contact sets on a sphere, both outcomes: the same verdict as the hull.
    rng = np.random.default_rng(7)
    verdicts = []
    for _ in range(60):
        points = rng.normal(size=(int(rng.integers(3, 5)), 3))
        points /= np.linalg.norm(points, axis=1, keepdims=True)
        normals = points + rng.normal(scale=0.3, size=points.shape)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        w = primitive_wrenches(points, normals, [0, 0, 0], 1.0, MU).reshape(-1, 6)
        verdicts.append(force_closure(w))
        assert verdicts[-1] == (epsilon(w) > 0.0)
    assert any(verdicts) and not all(verdicts)
    # Too few, non-finite or malformed wrenches: never force closure.
    assert not force_closure(np.zeros((6, 6)))
    assert not force_closure(np.full((12, 6), np.nan))
    assert not force_closure(np.zeros((12, 5)))


def test_cross_is_numpys() -> None:
    from sahgrasp.quality.wrench import _cross

    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(4, 8, 3)), rng.normal(size=(4, 8, 3))
    assert np.array_equal(_cross(a, b), np.cross(a, b))
