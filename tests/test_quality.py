"""Tests of the manipulability indices on ellipsoids computed by hand."""

from __future__ import annotations

import numpy as np
import pytest

from sahgrasp.atlas import AtlasSettings, build_atlas
from sahgrasp.atlas._quality import orthogonal_tail
from sahgrasp.atlas._quality import semi_axes as compiled_semi_axes
from sahgrasp.core.errors import QualityError
from sahgrasp.quality.ellipsoids import (
    INDICES,
    SINGULAR_THRESHOLDS,
    ellipsoid_indices,
    evaluate_index,
    full_rank_null_space,
    manipulability,
    null_space,
    principal_projection,
    semi_axes,
)


def test_identity_actuation_gives_the_object_map_singular_values() -> None:
    m = ellipsoid_indices(np.eye(3), np.diag([0.5, 2.0, 1.0]))
    assert np.allclose(m.semi_axes, [2.0, 1.0, 0.5])
    assert m.inverse_condition == pytest.approx(0.25)
    assert m.volume == pytest.approx(1.0)
    assert m.min_semiaxis == pytest.approx(0.5)


def test_fast_joints_shrink_the_ellipsoid() -> None:
    # qdot = diag(2, 1) tau and nu = tau: a unit joint speed moves the object 0.5 along x, 1 along y
    assert np.allclose(semi_axes(np.diag([2.0, 1.0]), np.eye(2)), [1.0, 0.5])


def test_redundant_actuation_matches_the_quadratic_form() -> None:
    rng = np.random.default_rng(3)
    A, B = rng.normal(size=(6, 3)), rng.normal(size=(3, 3))
    # {B tau : tau^T A^T A tau <= 1}: squared semi-axes = eigenvalues of B (A^T A)^-1 B^T
    expected = np.sqrt(np.sort(np.linalg.eigvalsh(B @ np.linalg.inv(A.T @ A) @ B.T))[::-1])
    assert np.allclose(semi_axes(A, B), expected)


def test_object_direction_out_of_reach_is_a_zero_semi_axis() -> None:
    m = ellipsoid_indices(np.eye(2), np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]]))
    assert np.allclose(m.semi_axes, [1.0, 1.0, 0.0])
    assert m.volume == 0.0 and m.inverse_condition == 0.0
    assert all(m.singular(name) for name in INDICES)


def test_motion_with_locked_joints_is_singular() -> None:
    A = np.array([[1.0, 0.0], [0.0, 0.0]])  # tau = (0, 1) moves the object without any joint
    m = ellipsoid_indices(A, np.eye(2))
    assert np.allclose(m.semi_axes, 0.0)
    assert all(m.singular(name) for name in INDICES)


def test_thresholds_of_the_paper() -> None:
    assert SINGULAR_THRESHOLDS == {"inverse_condition": 1e-3, "volume": 1e-4, "min_semiaxis": 1e-3}
    m = ellipsoid_indices(np.eye(2), np.diag([1.0, 2e-3]))  # volume 2e-3, inverse cond 2e-3
    assert not m.singular("volume") and not m.singular("inverse_condition")
    m = ellipsoid_indices(np.eye(2), np.diag([1.0, 5e-4]))
    assert m.singular("inverse_condition") and m.singular("min_semiaxis")
    with pytest.raises(QualityError, match="valid"):
        m.index("dexterity")


def test_rows_or_matrices_of_a_tangent_basis_and_batches() -> None:
    rng = np.random.default_rng(0)
    T = rng.normal(size=(5, 7, 3))  # five grasps, n = 7, t = 3
    actuated, obj = np.array([0, 1, 2, 3]), np.array([4, 5, 6])
    by_rows = manipulability(T, actuated, obj)
    selector = np.eye(7)
    by_matrix = manipulability(T, selector[actuated], selector[obj])
    assert by_rows.semi_axes.shape == (5, 3)
    assert np.allclose(by_rows.semi_axes, by_matrix.semi_axes)
    single = manipulability(T[2], actuated, obj)
    assert np.allclose(single.volume, by_rows.volume[2])
    with pytest.raises(QualityError, match="1-D"):
        manipulability(T, actuated[None, :], obj)


def test_null_space_is_an_orthonormal_tangent_basis() -> None:
    jac = np.random.default_rng(1).normal(size=(4, 2, 5))
    N = null_space(jac, 3)
    assert N.shape == (4, 5, 3)
    assert np.allclose(jac @ N, 0.0, atol=1e-12)
    assert np.allclose(np.swapaxes(N, 1, 2) @ N, np.eye(3), atol=1e-12)


def test_full_rank_null_space_spans_the_null_space_of_the_svd() -> None:
    jac = np.random.default_rng(2).normal(size=(4, 3, 7))
    N = full_rank_null_space(jac)
    assert N.shape == (4, 7, 4)
    assert np.allclose(jac @ N, 0.0, atol=1e-12)
    assert np.allclose(np.swapaxes(N, 1, 2) @ N, np.eye(4), atol=1e-12)
    reference = null_space(jac, 4)  # the same space: each basis is a rotation of the other
    rotation = np.swapaxes(reference, 1, 2) @ N
    assert np.allclose(np.swapaxes(rotation, 1, 2) @ rotation, np.eye(4), atol=1e-12)


@pytest.mark.parametrize(("n", "m"), [(2, 1), (5, 3), (19, 16)])
def test_compiled_orthogonal_tail_equals_numpys_complete_q(n: int, m: int) -> None:
    a = np.random.default_rng(n).normal(size=(6, n, m))
    h, tau = np.linalg.qr(a, mode="raw")
    tail = np.empty((6, n, n - m))
    orthogonal_tail(np.ascontiguousarray(h), tau, tail)
    q = np.linalg.qr(a, mode="complete")[0]
    assert np.allclose(tail, q[:, :, m:], rtol=0.0, atol=1e-14)
    with pytest.raises(ValueError, match="out: expected shape"):
        orthogonal_tail(np.ascontiguousarray(h), tau, np.empty((6, n, n)))


def reference_semi_axes(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """The semi-axes by numpy's SVDs (what ``atlas._quality.semi_axes`` compiles)."""
    _, s, vt = np.linalg.svd(A, full_matrices=False)  # A = U S V^T
    deficient = s[..., -1] <= 1e-12 * s[..., 0]
    M = (B @ np.swapaxes(vt, -1, -2)) / np.where(deficient[..., None], 1.0, s)[..., None, :]
    sigma = np.linalg.svd(M, compute_uv=False)
    axes = np.zeros((*sigma.shape[:-1], B.shape[-2]))
    axes[..., : min(B.shape[-2], sigma.shape[-1])] = sigma[..., : B.shape[-2]]
    axes[deficient] = 0.0
    return axes


@pytest.mark.parametrize(("a", "t", "o"), [(6, 3, 3), (10, 4, 6), (2, 3, 3), (3, 3, 1), (1, 1, 1)])
def test_compiled_semi_axes_equal_numpys_svds(a: int, t: int, o: int) -> None:
    rng = np.random.default_rng(a + 10 * t + 100 * o)
    A, B = rng.normal(size=(60, a, t)), rng.normal(size=(60, o, t))
    A[0] = 0.0  # rank deficient: all semi-axes zero
    A[1] *= np.logspace(0, -14, t)  # nearly so
    assert np.allclose(semi_axes(A, B), reference_semi_axes(A, B), rtol=1e-12, atol=1e-14)
    assert not semi_axes(A, B)[0].any()
    assert semi_axes(A[:, None], B[None, :3]).shape == (60, 3, o)  # batch shapes broadcast
    with pytest.raises(ValueError, match="out: expected shape"):
        compiled_semi_axes(A, B, np.empty((60, o + 1)), 1e-12)


def sphere_atlas():  # type: ignore[no-untyped-def]
    def f(x: np.ndarray) -> np.ndarray:
        return np.array([x @ x - 1.0])

    def j(x: np.ndarray) -> np.ndarray:
        return 2.0 * x[None, :]

    return build_atlas(f, j, [0.0, 0.0, 1.0], 2, AtlasSettings(radius=0.3))


def test_evaluate_index_accepts_user_callables() -> None:
    atlas = sphere_atlas()
    height = evaluate_index(atlas, lambda X: X[:, 2])
    assert height.values.shape == (atlas.n_charts,)
    assert height.best == 0  # the start point is the north pole
    assert atlas.centres[height.worst, 2] == height.values.min()
    scalar = evaluate_index(atlas, lambda x: -x[0], vectorised=False)
    assert atlas.centres[scalar.best, 0] == atlas.centres[:, 0].min()
    with pytest.raises(QualityError, match="values for"):
        evaluate_index(atlas, lambda X: X[:3, 0])
    with pytest.raises(QualityError, match="NaN"):
        evaluate_index(atlas, lambda X: np.full(len(X), np.nan))


def test_evaluate_index_ranks_candidates_only() -> None:
    atlas = sphere_atlas()
    north = atlas.centres[:, 2] > 0.5
    ranked = evaluate_index(atlas, lambda X: -X[:, 2], candidates=~north)
    assert ranked.best_overall == int(np.argmin(atlas.centres[:, 2]))
    assert not north[ranked.best] and not north[ranked.worst]
    assert ranked.values[ranked.worst] == ranked.values[~north].min()
    with pytest.raises(QualityError, match="no candidate chart"):
        evaluate_index(atlas, lambda X: X[:, 2], candidates=np.zeros(atlas.n_charts, bool))
    with pytest.raises(QualityError, match="candidates must be"):
        evaluate_index(atlas, lambda X: X[:, 2], candidates=[True])


def test_principal_projection_keeps_the_widest_directions() -> None:
    rng = np.random.default_rng(3)
    points = rng.normal(size=(500, 3)) * [0.01, 2.0, 1.0] + [5.0, 0.0, 0.0]
    xy = principal_projection(points)
    assert xy.shape == (500, 2)
    assert np.allclose(xy.mean(axis=0), 0.0)
    assert abs(np.corrcoef(xy[:, 0], points[:, 1])[0, 1]) > 0.99  # the widest axis first
    assert abs(np.corrcoef(xy[:, 1], points[:, 2])[0, 1]) > 0.99
