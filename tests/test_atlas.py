"""Tests of the generic continuation engine on spheres, a torus, a cap and singular curves."""

from __future__ import annotations

import itertools
import subprocess
import sys
from dataclasses import fields
from math import gamma, pi
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sahgrasp.atlas import Atlas, AtlasSettings, build_atlas, project
from sahgrasp.atlas._polytope import det_signs, min_singular_values
from sahgrasp.atlas.polytope import Polytope
from sahgrasp.core.errors import AtlasError

REPOSITORY = Path(__file__).resolve().parents[1]


def sphere_f(x: np.ndarray) -> np.ndarray:
    return np.array([x @ x - 1.0])


def sphere_j(x: np.ndarray) -> np.ndarray:
    return 2.0 * x[None, :]


TORUS_R, TORUS_RHO = 1.0, 0.4


def torus_f(x: np.ndarray) -> np.ndarray:
    q = np.hypot(x[0], x[1])
    return np.array([(q - TORUS_R) ** 2 + x[2] ** 2 - TORUS_RHO**2])


def torus_j(x: np.ndarray) -> np.ndarray:
    q = np.hypot(x[0], x[1])
    g = 2.0 * (q - TORUS_R) / q
    return np.array([[g * x[0], g * x[1], 2.0 * x[2]]])


def lemniscate_f(p: np.ndarray) -> np.ndarray:
    return np.array([(p @ p) ** 2 - 2.0 * (p[0] ** 2 - p[1] ** 2)])


def lemniscate_j(p: np.ndarray) -> np.ndarray:
    s = p @ p
    return np.array([[4.0 * s * p[0] - 4.0 * p[0], 4.0 * s * p[1] + 4.0 * p[1]]])


def sphere_volume(n: int) -> float:
    """Volume of the unit sphere S^(n-1) in R^n."""
    return 2.0 * pi ** (n / 2) / gamma(n / 2)


def check_on_manifold(atlas: Atlas, F, J) -> None:  # type: ignore[no-untyped-def]
    assert max(np.linalg.norm(F(x)) for x in atlas.centres) <= 1e-8
    for x, phi in zip(atlas.centres[::7], atlas.tangents[::7], strict=True):
        assert np.allclose(phi.T @ phi, np.eye(atlas.dim), atol=1e-10)
        assert np.allclose(J(x) @ phi, 0.0, atol=1e-8)


@pytest.mark.parametrize("batch", [1, 32])  # the one-chart engine and the wave (the default)
@pytest.mark.parametrize(("n", "r"), [(2, 0.1), (3, 0.15), (4, 0.3)])
def test_spheres_are_covered_with_vol_over_r_to_the_k_charts(n: int, r: float, batch: int) -> None:
    settings = AtlasSettings(radius=r, batch=batch)
    atlas = build_atlas(sphere_f, sphere_j, np.eye(n)[0], n - 1, settings)
    assert atlas.complete
    expected = sphere_volume(n) / r ** (n - 1)
    assert abs(atlas.n_charts / expected - 1.0) <= 0.10
    check_on_manifold(atlas, sphere_f, sphere_j)
    assert atlas.singular_points.shape == (0, n)
    assert not atlas.boundary.any()


@pytest.mark.parametrize(("n", "r"), [(3, 0.15), (4, 0.3)])
def test_sphere_has_no_hole(n: int, r: float) -> None:
    atlas = build_atlas(sphere_f, sphere_j, np.eye(n)[-1], n - 1, AtlasSettings(radius=r))
    points = np.random.default_rng(0).normal(size=(50_000, n))
    points /= np.linalg.norm(points, axis=1)[:, None]
    distance, _ = cKDTree(atlas.centres).query(points)
    assert distance.max() <= r


def test_torus_is_covered() -> None:
    r = 0.15
    atlas = build_atlas(torus_f, torus_j, [TORUS_R + TORUS_RHO, 0, 0], 2, AtlasSettings(radius=r))
    assert atlas.complete
    area = 4.0 * pi**2 * TORUS_R * TORUS_RHO
    assert abs(atlas.n_charts / (area / r**2) - 1.0) <= 0.10
    check_on_manifold(atlas, torus_f, torus_j)


def test_edges_join_close_charts_and_parents_are_neighbours() -> None:
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, AtlasSettings(radius=0.2))
    i, j = atlas.edges.T
    assert (i < j).all()
    assert (np.linalg.norm(atlas.centres[i] - atlas.centres[j], axis=1) < 2 * atlas.radius).all()
    assert atlas.parents[0] == -1
    for child in (1, 10, atlas.n_charts - 1):
        assert atlas.parents[child] in atlas.neighbours(child)


@pytest.mark.parametrize("batch", [1, 32])
def test_box_bound_stops_the_atlas_at_the_bound(batch: int) -> None:
    r, z_min = 0.1, 0.5
    lower = [-np.inf, -np.inf, z_min]
    settings = AtlasSettings(radius=r, batch=batch)
    atlas = build_atlas(sphere_f, sphere_j, [0, 0, 1], 2, settings, lower=lower)
    assert atlas.complete
    assert (atlas.centres[:, 2] >= z_min).all()
    assert atlas.boundary.any()
    assert atlas.centres[atlas.boundary, 2].min() < z_min + r
    cap = np.random.default_rng(1).normal(size=(50_000, 3))
    cap /= np.linalg.norm(cap, axis=1)[:, None]
    cap = cap[cap[:, 2] >= z_min]
    distance, _ = cKDTree(atlas.centres).query(cap)
    assert distance.max() <= r
    area = 2.0 * pi * (1.0 - z_min)
    assert abs(atlas.n_charts / (area / r**2) - 1.0) <= 0.15


@pytest.mark.parametrize("batch", [1, 32])
def test_crossing_of_a_lemniscate_is_reported_and_passed(batch: int) -> None:
    start = [np.sqrt(2.0), 0.0]
    settings = AtlasSettings(radius=0.1, batch=batch)
    atlas = build_atlas(lemniscate_f, lemniscate_j, start, 1, settings)
    assert atlas.complete
    assert len(atlas.singular_points) == 1
    assert np.linalg.norm(atlas.singular_points[0]) < 0.01
    assert atlas.centres[:, 0].min() < -1.3  # the far lobe was reached through the crossing


def test_rank_drop_at_a_centre_is_reported() -> None:
    def f(p: np.ndarray) -> np.ndarray:
        return np.array([p[0] * p[1]])

    def j(p: np.ndarray) -> np.ndarray:
        return np.array([[p[1], p[0]]])

    settings = AtlasSettings(radius=0.1)
    atlas = build_atlas(f, j, [0.5, 0.0], 1, settings, lower=[-1, -1], upper=[1, 1])
    assert atlas.complete
    assert len(atlas.singular_points) == 1
    assert np.linalg.norm(atlas.singular_points[0]) < 1e-6


def test_max_charts_leaves_an_open_frontier() -> None:
    settings = AtlasSettings(radius=0.1, max_charts=50)
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, settings)
    assert atlas.n_charts == 50
    assert not atlas.complete and atlas.stop_reason == "max_charts"
    assert atlas.open.any()


def test_a_finished_atlas_says_complete() -> None:
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, AtlasSettings(radius=0.5))
    assert atlas.complete and atlas.stop_reason == "complete"


def test_progress_hears_of_every_chart() -> None:
    heard: list[tuple[str, int, int | None]] = []
    settings = AtlasSettings(radius=0.2, max_charts=30)
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, settings,
                        progress=lambda *report: heard.append(report))  # fmt: skip
    assert [done for _, done, _ in heard] == [*range(1, atlas.n_charts + 1), atlas.n_charts]
    assert {stage for stage, _, _ in heard} == {"atlas charts"}
    assert all(done <= total <= 30 for _, done, total in heard if total is not None)


@pytest.mark.parametrize("batch", [1, 32])
def test_progress_counts_to_the_end_of_the_atlas_not_to_max_charts(batch: int) -> None:
    heard: list[tuple[int, int | None]] = []
    settings = AtlasSettings(radius=0.3, max_charts=100_000, batch=batch)
    atlas = build_atlas(
        sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, settings,
        progress=lambda _stage, done, total: heard.append((done, total)),
    )  # fmt: skip
    assert atlas.complete
    # The total is the charts built plus the open frontier: never the cap, and it ends at 100%.
    assert all(total is not None and done <= total < 100_000 for done, total in heard)
    assert heard[-1] == (atlas.n_charts, atlas.n_charts)
    assert max(total for _, total in heard if total is not None) <= 2 * atlas.n_charts


@pytest.mark.parametrize("radius", [1e6, 30.0])
def test_a_radius_far_larger_than_the_manifold_stalls_and_is_not_complete(radius: float) -> None:
    bounded = AtlasSettings(radius=radius, epsilon=0.1)
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, bounded)
    assert atlas.n_charts == 1
    assert (atlas.stop_reason, atlas.complete) == ("stalled", False)


def test_a_radius_below_the_newton_tolerance_is_refused() -> None:
    with pytest.raises(AtlasError, match=r"radius must be >= 1000 \* newton_tol"):
        AtlasSettings(radius=1e-300)


def test_progress_setting_draws_a_bar_on_stderr(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # bars are drawn on a terminal only
    settings = AtlasSettings(radius=0.5, progress=True)
    build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, settings)
    captured = capsys.readouterr()
    assert captured.out == "" and "atlas charts" in captured.err


def test_start_point_is_projected_onto_the_manifold() -> None:
    atlas = build_atlas(sphere_f, sphere_j, [1.0 + 1e-8, 0.0, 0.0], 2, AtlasSettings(max_charts=1))
    assert abs(np.linalg.norm(atlas.centres[0]) - 1.0) <= 1e-12


def test_project_solves_eq_15() -> None:
    phi = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    x_tilde = np.array([1.0, 0.3, -0.2])
    x = project(sphere_f, sphere_j, x_tilde, phi)
    assert x is not None
    assert abs(x @ x - 1.0) <= 1e-10
    assert np.allclose(phi.T @ (x - x_tilde), 0.0)
    assert project(sphere_f, sphere_j, np.array([0.0, 2.0, 0.0]), phi) is None


@pytest.mark.parametrize(
    ("x0", "k", "f", "j", "match"),
    [
        ([1.0, 0.0, 0.0], 1, sphere_f, sphere_j, "shape"),
        ([1.0, 0.0, 0.0], 3, sphere_f, sphere_j, "1 <= k < n"),
        ([1.0, 0.0, 0.0], 0, sphere_f, sphere_j, "1 <= k < n"),
        ([1.0, 0.0, 0.0], 2, sphere_f, lambda x: 2.0 * x, "shape"),
        ([1.1, 0.0, 0.0], 2, sphere_f, sphere_j, "off the manifold"),
        ([np.nan, 0.0, 0.0], 2, sphere_f, sphere_j, "finite"),
        ([[1.0, 0.0, 0.0]], 2, sphere_f, sphere_j, "1-D"),
        (
            [0.0, 0.0],
            1,
            lambda p: np.array([p[0] * p[1]]),
            lambda p: np.array([[p[1], p[0]]]),
            "rank",
        ),
    ],
)
def test_bad_input_raises_atlas_error(x0, k, f, j, match) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(AtlasError, match=match):
        build_atlas(f, j, x0, k)


def test_bad_bounds_and_settings_raise_atlas_error() -> None:
    with pytest.raises(AtlasError, match="outside the box"):
        build_atlas(sphere_f, sphere_j, [1.0, 0, 0], 2, lower=[-1, -1, 0.5])
    with pytest.raises(AtlasError, match="3 numbers"):
        build_atlas(sphere_f, sphere_j, [1.0, 0, 0], 2, upper=[1, 1])
    with pytest.raises(AtlasError, match="epsilon"):
        AtlasSettings(epsilon=1.5)
    with pytest.raises(AtlasError, match="radius"):
        AtlasSettings(radius=-0.1)


def assert_same_atlas(a: Atlas, b: Atlas) -> None:
    for field in fields(Atlas):
        if field.name != "build_seconds":
            assert np.array_equal(getattr(a, field.name), getattr(b, field.name)), field.name


@pytest.mark.parametrize("batch", [1, 32])
@pytest.mark.parametrize(("n", "r"), [(3, 0.2), (4, 0.4)])
def test_the_same_input_gives_the_same_atlas(n: int, r: float, batch: int) -> None:
    settings = AtlasSettings(radius=r, batch=batch)
    build = lambda: build_atlas(sphere_f, sphere_j, np.eye(n)[0], n - 1, settings)  # noqa: E731
    assert_same_atlas(build(), build())


def test_bounded_atlas_is_deterministic_and_its_records_agree() -> None:
    settings = AtlasSettings(radius=0.2)
    build = lambda: build_atlas(sphere_f, sphere_j, [0, 0, 1.0], 2, settings, lower=[-2, -2, 0.3])  # noqa: E731
    atlas = build()
    assert_same_atlas(atlas, build())
    assert atlas.boundary.any() and not atlas.boundary.all() and atlas.complete
    assert atlas.parents[0] == -1 and (atlas.parents[1:] < np.arange(1, atlas.n_charts)).all()
    assert (atlas.edges[:, 0] < atlas.edges[:, 1]).all()


@pytest.mark.parametrize("k", [2, 3])
@pytest.mark.parametrize("seed", range(5))
def test_polytope_from_all_planes_equals_one_cut_per_plane(seed: int, k: int) -> None:
    rng = np.random.default_rng(seed)
    r = 0.1
    u = rng.normal(size=(20, k))
    u *= (rng.uniform(0.5, 2.0, 20) * r / np.linalg.norm(u, axis=1))[:, None]
    planes, offsets = u.tolist(), (0.5 * np.einsum("ij,ij->i", u, u)).tolist()
    at_once = Polytope.from_planes(k, r, planes, offsets, 1e-9 * r)
    one_by_one = Polytope.cube(k, r)
    for a, b in zip(planes, offsets, strict=True):
        one_by_one.cut(a, b, 1e-9 * r)
    gap, _ = cKDTree(at_once.verts).query(one_by_one.verts)
    assert len(at_once.verts) == len(one_by_one.verts) and gap.max() <= 1e-12
    assert at_once.reach2 == pytest.approx(one_by_one.reach2)
    if k == 2:  # the polygon clip keeps the vertices counter-clockwise, as the dual build does
        for poly in (at_once, one_by_one):
            x, y = np.array(poly.verts).T
            assert np.all(x * np.roll(y, -1) - np.roll(x, -1) * y > 0)


def test_import_loads_neither_pinocchio_nor_tqdm() -> None:
    code = (
        "import sys, sahgrasp.atlas; "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('pinocchio', 'tqdm')))"
    )
    env = {"PYTHONPATH": str(REPOSITORY), "PATH": ""}
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True
    )
    assert done.stdout.strip() == "[]"


def test_polytope_rejects_bad_input_with_a_clear_error() -> None:
    with pytest.raises(ValueError, match="k must be"):
        Polytope.cube(0, 0.1)
    poly = Polytope.cube(3, 0.1)
    with pytest.raises(ValueError, match="a must have 3 entries"):
        poly.cut([1.0, 0.0], 0.05, 1e-10)
    with pytest.raises(ValueError, match="not one of the polytope's"):
        poly.index((0.0, 0.0, 0.0))
    with pytest.raises(IndexError):
        poly.vertex(8)
    with pytest.raises(ValueError, match="same length"):
        Polytope.from_planes(2, 0.1, [[0.1, 0.0]], [], 1e-10)


def test_polytope_copy_block_and_index() -> None:
    poly = Polytope.cube(2, 0.1)
    assert poly.verts == [(-0.1, -0.1), (0.1, -0.1), (0.1, 0.1), (-0.1, 0.1)]
    assert poly.masks == [0b1010, 0b1001, 0b0101, 0b0110]  # face 2d+s is x_d = -+r
    copy = poly.copy()
    assert copy.cut([1.0, 0.0], 0.05, 1e-10) and not poly.cut([1.0, 0.0], 0.2, 1e-10)
    assert len(poly) == 4 and max(x for x, _ in copy.verts) == pytest.approx(0.05)
    poly.block(poly.expandable(0.0))
    assert poly.blocked == [True, False, False, False] and poly.expandable(0.0) == 1
    assert poly.index(poly.vertex(2)) == 2 and poly.vertex_norm2(2) == pytest.approx(0.02)


def _brute_force_vertices(k: int, r: float, planes: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Vertices of ``{|w_d| <= r, planes @ w <= offsets}``: every k tight constraints, solved."""
    A = np.concatenate((np.eye(k), -np.eye(k), planes))
    b = np.concatenate((np.full(2 * k, r), offsets))
    found = []
    for rows in itertools.combinations(range(len(A)), k):
        M = A[list(rows)]
        if abs(np.linalg.det(M)) < 1e-12:
            continue
        w = np.linalg.solve(M, b[list(rows)])
        if (A @ w <= b + 1e-12).all():
            found.append(w)
    return np.unique(np.round(np.array(found), 12), axis=0)


@pytest.mark.parametrize("k", [2, 3])
@pytest.mark.parametrize("seed", range(6))
def test_polytope_cuts_give_the_brute_force_vertices(seed: int, k: int) -> None:
    rng = np.random.default_rng(100 + seed)
    r = 0.1
    u = rng.normal(size=(8, k))
    u *= (rng.uniform(0.6, 1.9, 8) * r / np.linalg.norm(u, axis=1))[:, None]
    offsets = 0.5 * np.einsum("ij,ij->i", u, u)
    poly = Polytope.cube(k, r)
    for a, b in zip(u.tolist(), offsets.tolist(), strict=True):
        poly.cut(a, b, 1e-9 * r)
    expected = _brute_force_vertices(k, r, u, offsets)
    got = np.array(poly.verts)
    assert len(got) == len(expected)
    gap, _ = cKDTree(expected).query(got)
    assert gap.max() <= 1e-12
    assert poly.reach2 == pytest.approx(float((expected**2).sum(axis=1).max()))


@pytest.mark.parametrize("n", [1, 2, 3, 19])
def test_compiled_determinant_signs_equal_numpys(n: int) -> None:
    rng = np.random.default_rng(n)
    a = rng.normal(size=(50, n, n))
    a[0] = 0.0  # singular: sign 0, as numpy's
    a[1, :, 0] = 0.0
    signs = np.empty(50)
    det_signs(a, signs)
    assert np.array_equal(signs, np.linalg.slogdet(a)[0])


@pytest.mark.parametrize(("rows", "k"), [(1, 1), (2, 2), (3, 3), (5, 2), (4, 4)])
def test_compiled_smallest_singular_values_equal_numpys(rows: int, k: int) -> None:
    a = np.random.default_rng(rows + k).normal(size=(50, rows, k))
    a[0] = 0.0
    sigma = np.empty(50)
    min_singular_values(a, sigma)
    assert np.allclose(sigma, np.linalg.svd(a, compute_uv=False)[:, -1], rtol=1e-12, atol=1e-12)


def test_compiled_linear_algebra_refuses_bad_arrays() -> None:
    out = np.empty(2)
    with pytest.raises(TypeError, match="C-contiguous float64"):
        det_signs(np.ones((2, 3, 3), dtype=np.float32), out)
    with pytest.raises(ValueError, match="n, n"):
        det_signs(np.ones((2, 3, 2)), out)
    with pytest.raises(ValueError, match="out"):
        min_singular_values(np.ones((3, 2, 2)), out)
    with pytest.raises(ValueError, match="rows >= cols"):
        min_singular_values(np.ones((2, 1, 2)), out)
    with pytest.raises(TypeError, match="float64"):
        det_signs(np.ones((2, 3, 3)), np.ones(2, dtype=np.int64))


def test_a_build_leaves_the_garbage_collector_as_it_found_it() -> None:
    import gc

    assert gc.get_freeze_count() == 0
    build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, AtlasSettings(radius=0.5))
    assert gc.get_freeze_count() == 0 and gc.isenabled()
    gc.freeze()  # a caller's own frozen objects stay frozen
    try:
        frozen = gc.get_freeze_count()
        build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, AtlasSettings(radius=0.5))
        assert gc.get_freeze_count() > 0.9 * frozen  # not unfrozen by the build
    finally:
        gc.unfreeze()
