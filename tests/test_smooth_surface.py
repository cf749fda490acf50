"""The smooth local model of a mesh (Monge patch, Eqs. (M1)-(M3)) against analytic surfaces."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from sahgrasp.objects.smooth_surface import SurfaceModelError, fit_mesh_patch

SPHERE_R = 0.04
CYLINDER_R = 0.03


def _sphere(subdivisions: int) -> trimesh.Trimesh:
    return trimesh.creation.icosphere(subdivisions, SPHERE_R)


def _cylinder(sections: int) -> trimesh.Trimesh:
    return trimesh.creation.cylinder(CYLINDER_R, 0.12, sections=sections)


def _contact(mesh: trimesh.Trimesh, kind: str) -> tuple[np.ndarray, np.ndarray]:
    d = np.array([1.0, 0.3, 0.2 if kind == "sphere" else 0.0])
    d /= np.linalg.norm(d)
    p = d * SPHERE_R if kind == "sphere" else d * CYLINDER_R + [0.0, 0.0, 0.01]
    closest, _, _ = trimesh.proximity.closest_point(mesh, [p])
    return closest[0], d


def _analytic_errors(patch, kind: str) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """Largest distance [m] and normal angle [deg] from the model to the analytic surface."""
    grid = np.linspace(-patch.half_width_m, patch.half_width_m, 11)
    distances, angles = [], []
    for u in grid:
        for v in grid:
            jet = patch.evaluate((u, v))
            if kind == "sphere":
                r = np.linalg.norm(jet.point)
                distances.append(abs(r - SPHERE_R))
                exact = jet.point / r
            else:
                r = np.hypot(*jet.point[:2])
                distances.append(abs(r - CYLINDER_R))
                exact = np.array([jet.point[0], jet.point[1], 0.0]) / r
            angles.append(np.degrees(np.arccos(np.clip(exact @ jet.normal, -1.0, 1.0))))
    return max(distances), max(angles)


# Stated tolerances (docs/methods/atlas.md, "The atlas on a mesh"): a coarse mesh (sphere of 320
# faces,
# edges about 12 mm on a 40 mm radius; cylinder of 24 sections) is itself up to 0.45 mm inside the
# surface between its vertices, and the model lies between facets and vertices; a fine one (5120
# faces, 128 sections) is followed to within 0.1 mm and 1.5 degrees over a patch of +-20 mm.
CASES = [
    ("sphere", _sphere(2), 0.8e-3, 3.0),
    ("sphere", _sphere(4), 0.1e-3, 1.5),
    ("cylinder", _cylinder(24), 0.3e-3, 1.0),
    ("cylinder", _cylinder(128), 0.06e-3, 1.0),
]


@pytest.mark.parametrize(("kind", "mesh", "point_tol_m", "normal_tol_deg"), CASES)
def test_the_model_follows_the_analytic_surface(
    kind: str, mesh: trimesh.Trimesh, point_tol_m: float, normal_tol_deg: float
) -> None:
    point, normal = _contact(mesh, kind)
    patch = fit_mesh_patch("index", mesh, point, normal)
    assert patch.half_width_m >= 0.011  # smooth: a wide patch is kept (at most 20 mm)
    distance, angle = _analytic_errors(patch, kind)
    assert distance <= point_tol_m and angle <= normal_tol_deg
    assert patch.fit_error_m <= 3e-4  # its own check against the mesh


def test_a_finer_mesh_gives_a_closer_model() -> None:
    errors = []
    for subdivisions in (2, 4):
        mesh = _sphere(subdivisions)
        patch = fit_mesh_patch("thumb", mesh, *_contact(mesh, "sphere"))
        errors.append(_analytic_errors(patch, "sphere")[0])
    assert errors[1] < errors[0] / 5


@pytest.mark.parametrize("kind", ["sphere", "cylinder"])
def test_point_and_normal_jacobians_match_finite_differences(kind: str) -> None:
    mesh = _sphere(3) if kind == "sphere" else _cylinder(64)
    patch = fit_mesh_patch("middle", mesh, *_contact(mesh, kind)).placed(
        trimesh.transformations.euler_matrix(0.3, -0.2, 0.5) @ np.diag([1, 1, 1, 1.0])
    )
    rng = np.random.default_rng(0)
    step = 1e-6
    for uv in rng.uniform(-0.01, 0.01, size=(5, 2)):
        jet = patch.evaluate(uv)
        assert np.linalg.norm(jet.normal) == pytest.approx(1.0, abs=1e-12)
        for col in range(2):
            e = np.eye(2)[col] * step
            plus, minus = patch.evaluate(uv + e), patch.evaluate(uv - e)
            dp = (plus.point - minus.point) / (2 * step)
            dn = (plus.normal - minus.normal) / (2 * step)
            assert np.allclose(jet.point_jacobian[:, col], dp, atol=1e-7)
            assert np.allclose(jet.normal_jacobian[:, col], dn, atol=1e-5)


def test_a_flat_face_is_modelled_exactly_and_a_corner_is_refused() -> None:
    box = trimesh.creation.box([0.06, 0.06, 0.06])
    patch = fit_mesh_patch("thumb", box, [0.0, 0.0, 0.03], [0.0, 0.0, 1.0])
    assert patch.fit_error_m <= 1e-9 and patch.normal_error_rad <= 1e-6
    near_edge = fit_mesh_patch("thumb", box, [0.0, 0.024, 0.03], [0.0, 0.0, 1.0])
    assert near_edge.half_width_m < 0.01  # shrunk to stay on the face
    with pytest.raises(SurfaceModelError, match="sharp edge, a corner"):
        fit_mesh_patch("thumb", box, [0.03, 0.03, 0.03], [0.0, 0.0, 1.0])


def test_bad_arguments_are_refused() -> None:
    box = trimesh.creation.box([0.06, 0.06, 0.06])
    with pytest.raises(SurfaceModelError, match="finite"):
        fit_mesh_patch("thumb", box, [0.0, 0.0, np.nan], [0.0, 0.0, 1.0])
    with pytest.raises(SurfaceModelError, match="min_half_width_m"):
        fit_mesh_patch("thumb", box, [0.0, 0.0, 0.03], [0.0, 0.0, 1.0], min_half_width_m=0.0)


@pytest.mark.parametrize(("kind", "mesh"), [("sphere", _sphere(4)), ("cylinder", _cylinder(128))])
def test_an_anchored_model_passes_through_the_contact_with_its_normal(
    kind: str, mesh: trimesh.Trimesh
) -> None:
    point, _ = _contact(mesh, kind)
    _, _, face = trimesh.proximity.closest_point(mesh, [point])
    normal = mesh.face_normals[face[0]]  # a facet's normal, as a planner's contact has
    free = fit_mesh_patch("thumb", mesh, point, normal)
    anchored = fit_mesh_patch("thumb", mesh, point, normal, anchored=True)
    jet = anchored.evaluate((0.0, 0.0))
    assert np.allclose(jet.point, point, atol=1e-12)
    assert np.allclose(jet.normal, normal, atol=1e-12)
    # Still a model of the mesh within the tolerance, as wide as the free fit where both fit.
    assert anchored.fit_error_m <= 3e-4
    assert anchored.half_width_m >= 0.75 * free.half_width_m
    # The free fit does not pass through the contact exactly (it averages the facets).
    assert np.linalg.norm(free.evaluate((0.0, 0.0)).point - point) > 1e-9


def test_the_model_far_outside_its_square_is_finite() -> None:
    # A diverging Newton step of the atlas's projection asks for such points: no overflow.
    patch = fit_mesh_patch("thumb", _sphere(4), *_contact(_sphere(4), "sphere"))
    jet = patch.evaluate((1e300, -1e300))
    assert np.isfinite(jet.point).all() and np.isfinite(jet.normal).all()
