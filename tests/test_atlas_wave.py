"""Tests of the wave-front expansion (``AtlasSettings.batch > 1``, the default) against
one-chart expansion (``batch = 1``)."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sahgrasp.atlas import Atlas, AtlasSettings, build_atlas
from sahgrasp.atlas.polytope import Polytope, compatible
from sahgrasp.core.errors import AtlasError
from sahgrasp.optimization.planar import make_planar_problem


def sphere_f(x: np.ndarray) -> np.ndarray:
    """``|x|^2 - 1`` of one point (n,) or a stack (B, n)."""
    return (x * x).sum(axis=-1, keepdims=True) - 1.0


def sphere_j(x: np.ndarray) -> np.ndarray:
    return 2.0 * x[..., None, :]


def lemniscate_f(p: np.ndarray) -> np.ndarray:
    s = (p * p).sum(axis=-1, keepdims=True)
    return s**2 - 2.0 * (p[..., :1] ** 2 - p[..., 1:] ** 2)


def lemniscate_j(p: np.ndarray) -> np.ndarray:
    s = (p * p).sum(axis=-1, keepdims=True)
    sign = np.array([-1.0, 1.0])
    return (4.0 * s * p + 4.0 * sign * p)[..., None, :]


def sphere_points(n: int, count: int, seed: int) -> np.ndarray:
    points = np.random.default_rng(seed).normal(size=(count, n))
    return points / np.linalg.norm(points, axis=1)[:, None]


def assert_same_atlas(a: Atlas, b: Atlas) -> None:
    for field in fields(Atlas):
        if field.name != "build_seconds":
            assert np.array_equal(getattr(a, field.name), getattr(b, field.name)), field.name


@pytest.mark.parametrize(("n", "r", "batch"), [(3, 0.15, 16), (3, 0.15, 64), (4, 0.3, 32)])
def test_a_wave_covers_the_sphere_with_the_charts_of_one_chart_expansion(
    n: int, r: float, batch: int
) -> None:
    settings = AtlasSettings(radius=r, batch=1)
    one = build_atlas(sphere_f, sphere_j, np.eye(n)[0], n - 1, settings)
    wave = build_atlas(
        sphere_f, sphere_j, np.eye(n)[0], n - 1, replace(settings, batch=batch), stacked=True
    )
    assert wave.complete and not wave.boundary.any()
    assert abs(wave.n_charts / one.n_charts - 1.0) <= 0.02
    distance, _ = cKDTree(wave.centres).query(sphere_points(n, 50_000, 0))
    assert distance.max() <= r
    assert np.abs(np.linalg.norm(wave.centres, axis=1) - 1.0).max() <= 1e-8
    phi = wave.tangents
    assert np.allclose(np.matmul(phi.transpose(0, 2, 1), phi), np.eye(n - 1), atol=1e-10)
    assert np.abs(np.matmul(wave.centres[:, None, :], phi)).max() <= 1e-8  # x is the normal


def test_a_wave_gives_the_same_atlas_every_time_with_or_without_stacked_functions() -> None:
    settings = AtlasSettings(radius=0.2, batch=24)
    build = lambda stacked: build_atlas(  # noqa: E731
        sphere_f, sphere_j, [0, 0, 1.0], 2, settings, lower=[-2, -2, 0.3], stacked=stacked
    )
    atlas = build(True)
    assert_same_atlas(atlas, build(True))
    rowwise = build(False)
    assert rowwise.n_charts == atlas.n_charts
    assert np.allclose(rowwise.centres, atlas.centres, atol=1e-12)
    assert atlas.complete and atlas.boundary.any()
    assert (atlas.centres[:, 2] >= 0.3).all()
    assert atlas.parents[0] == -1 and (atlas.parents[1:] < np.arange(1, atlas.n_charts)).all()
    assert (atlas.edges[:, 0] < atlas.edges[:, 1]).all()


def test_a_wave_stops_at_a_box_bound_and_covers_the_cap() -> None:
    r, z_min = 0.1, 0.5
    settings = AtlasSettings(radius=r, batch=32)
    atlas = build_atlas(sphere_f, sphere_j, [0, 0, 1], 2, settings, lower=[-2, -2, z_min])
    assert atlas.complete and atlas.boundary.any()
    assert (atlas.centres[:, 2] >= z_min).all()
    cap = sphere_points(3, 50_000, 1)
    distance, _ = cKDTree(atlas.centres).query(cap[cap[:, 2] >= z_min])
    assert distance.max() <= r


def test_a_wave_reports_and_passes_the_crossing_of_a_lemniscate() -> None:
    settings = AtlasSettings(radius=0.1, batch=8)
    atlas = build_atlas(lemniscate_f, lemniscate_j, [np.sqrt(2.0), 0.0], 1, settings, stacked=True)
    assert atlas.complete
    assert len(atlas.singular_points) == 1
    assert np.linalg.norm(atlas.singular_points[0]) < 0.01
    assert atlas.centres[:, 0].min() < -1.3  # the far lobe was reached through the crossing


def test_a_wave_stops_at_max_charts() -> None:
    settings = AtlasSettings(radius=0.1, max_charts=50, batch=32)
    atlas = build_atlas(sphere_f, sphere_j, [1.0, 0.0, 0.0], 2, settings, stacked=True)
    assert atlas.n_charts == 50 and atlas.stop_reason == "max_charts"


def test_a_wave_atlas_of_the_planar_hand_is_complete_and_as_large() -> None:
    problem = make_planar_problem()
    settings = AtlasSettings(radius=0.125, epsilon=0.4, max_charts=20_000, batch=1)
    build = lambda s, stacked: build_atlas(  # noqa: E731
        problem.F, problem.J, problem.start, problem.dimension, s, *problem.bounds(),
        stacked=stacked,
    )  # fmt: skip
    one = build(settings, False)
    wave = build(replace(settings, batch=32), True)
    assert wave.complete
    assert abs(wave.n_charts / one.n_charts - 1.0) <= 0.03  # another order of expansion
    lower, upper = problem.bounds()
    assert ((wave.centres >= lower) & (wave.centres <= upper)).all()
    assert np.abs(problem.F(wave.centres)).max() <= 1e-8


def test_batch_below_one_raises_atlas_error() -> None:
    with pytest.raises(AtlasError, match="batch"):
        AtlasSettings(batch=0)


class _OnePointCache:
    """``F`` and ``J`` of the unit sphere sharing the work of the last point, as the SAH's do."""

    def __init__(self) -> None:
        self.last = b""
        self.misses = 0  # points whose shared work was done

    def _work(self, x: np.ndarray) -> None:
        if x.tobytes() != self.last:
            self.last = x.tobytes()
            self.misses += 1

    def F(self, x: np.ndarray) -> np.ndarray:
        self._work(x)
        return np.array([x @ x - 1.0])

    def J(self, x: np.ndarray) -> np.ndarray:
        self._work(x)
        return 2.0 * x[None]


@pytest.mark.parametrize("r", [0.1, 0.2])
def test_a_wave_does_a_point_by_point_f_and_j_work_about_as_often_as_one_chart_expansion(
    r: float,
) -> None:
    # J right after F at each point keeps the shared work, and a try that would be left out is
    # deferred before its projection: no work is done twice (it was 2.8-3.6x before).
    misses = {}
    for batch in (1, 32):
        cache = _OnePointCache()
        settings = AtlasSettings(radius=r, batch=batch)
        atlas = build_atlas(cache.F, cache.J, [0, 0, 1.0], 2, settings, lower=[-2, -2, -0.5])
        assert atlas.complete
        misses[batch] = cache.misses
    assert misses[32] <= 1.05 * misses[1]


def reference_compatible(
    polys: list[Polytope],
    x: np.ndarray,
    parent_x: np.ndarray,
    phi: np.ndarray,
    parent_phi: np.ndarray,
    vertices: np.ndarray,
    r: float,
    tol: float,
    threshold: float,
) -> list[int]:
    """The wave's compatibility test in plain numpy and Python (what ``compatible`` compiles)."""
    count = len(vertices)
    accepted: list[int] = []
    gone = [False] * count
    for q in range(count):
        if gone[q]:
            continue
        state = []  # per earlier accepted p: 1 its plane cuts off q's vertex, 2 it is nearer
        planes = []
        for p in accepted:
            diff = x[p] - parent_x[q]
            a = diff @ parent_phi[q]
            b = 0.5 * (a @ a)
            if not (diff @ diff < 4 * r * r and tol * r < b):
                continue
            M = phi[p].T @ parent_phi[q]
            if np.linalg.svd(M, compute_uv=False)[-1] ** 2 < threshold:
                continue  # another branch: no plane
            if a @ vertices[q] - b > tol:
                state.append(1)
            elif 0.5 * b < vertices[q] @ vertices[q]:
                planes.append((a.tolist(), b))
        if 1 in state:
            continue
        poly = polys[q].copy()
        for a, b in planes:
            if 0.5 * b < poly.reach2:
                poly.cut(a, b, tol)
        v = poly.expandable(r * r)
        if planes and (v < 0 or poly.vertex(v) != tuple(vertices[q])):
            continue
        accepted.append(q)
    return accepted


@pytest.mark.parametrize("k", [1, 2, 3])
def test_compiled_compatibility_test_equals_the_reference(k: int) -> None:
    n, r, tol, count = k + 2, 0.3, 1e-9 * 0.3, 12
    kept = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        parent_x = rng.normal(scale=0.25, size=(count, n))
        parent_phi = np.linalg.qr(rng.normal(size=(count, n, k)))[0]
        phi = np.linalg.qr(parent_phi + rng.normal(scale=0.6, size=(count, n, k)))[0]
        polys, vertices = [], []
        for _ in range(count):
            planes = rng.normal(size=(3, k))
            poly = Polytope.from_planes(
                k, r, planes.tolist(), rng.uniform(0.1, 0.3, 3).tolist(), tol
            )
            v = poly.expandable(r * r)
            v = v if v >= 0 else 0
            polys.append(poly)
            vertices.append(poly.vertex(v))
        verts = np.array(vertices)
        x = parent_x + np.einsum(
            "qnk,qk->qn", parent_phi, r * verts / np.linalg.norm(verts, axis=1)[:, None]
        )
        threshold = 0.3
        got = compatible(polys, x, parent_x, phi, parent_phi, verts, r, r * r, tol, threshold)
        assert got == reference_compatible(
            polys, x, parent_x, phi, parent_phi, verts, r, tol, threshold
        )
        kept += len(got)
    assert 0 < kept < 40 * count  # both outcomes occur


@pytest.mark.parametrize(
    ("bad", "error", "message"),
    [
        ({"centres": np.ones((1, 3), dtype=np.float32)}, TypeError, "float64"),
        ({"vertices": np.ones((1, 3))}, ValueError, "vertices: expected shape"),
        ({"polys": [None]}, TypeError, "polytope"),
    ],
)
def test_compiled_compatibility_test_refuses_bad_arrays(
    bad: dict[str, object], error: type[Exception], message: str
) -> None:
    arguments: dict[str, object] = {
        "polys": [Polytope.cube(2, 0.1)],
        "centres": np.ones((1, 3)),
        "parent_centres": np.ones((1, 3)),
        "phi": np.ones((1, 3, 2)),
        "parent_phi": np.ones((1, 3, 2)),
        "vertices": np.ones((1, 2)),
    }
    arguments.update(bad)
    with pytest.raises(error, match=message):
        compatible(*arguments.values(), 0.1, 0.01, 1e-10, 0.5)
