import math

import numpy as np
import pytest
import trimesh.creation
import trimesh.triangles

from sahgrasp.core.errors import SahGraspError
from sahgrasp.ik import solve_ik
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import load_object
from sahgrasp.objects.grasp_sampler import (
    FINGERS,
    GraspSamplingError,
    HandReach,
    SamplerSettings,
    SurfaceMesh,
    registered_reach,
    sample_contact_sets,
    sample_object_grasps,
)

SAH_REACH = registered_reach("sah")
"""The SAH's measured reach (the hand registry's)."""

HALF_BOX_M = np.array([0.03, 0.05, 0.04])
CYLINDER_RADIUS_M, CYLINDER_HEIGHT_M = 0.03, 0.10


@pytest.fixture(scope="module")
def box_sets() -> list[GraspTarget]:
    return sample_contact_sets(trimesh.creation.box(2 * HALF_BOX_M), 20, seed=101)


@pytest.fixture(scope="module")
def cylinder() -> trimesh.Trimesh:
    return trimesh.creation.cylinder(CYLINDER_RADIUS_M, CYLINDER_HEIGHT_M, sections=64)


def _arrays(targets: list[GraspTarget]) -> tuple[np.ndarray, np.ndarray]:
    points = np.array([[c.point for c in t.contacts] for t in targets])
    normals = np.array([[c.normal for c in t.contacts] for t in targets])
    return points, normals


def _mesh_distance(triangles: np.ndarray, point: np.ndarray) -> float:
    closest = trimesh.triangles.closest_point(triangles, np.tile(point, (len(triangles), 1)))
    return float(np.linalg.norm(closest - point, axis=1).min())


def test_box_contacts_lie_on_the_faces_with_outward_face_normals(box_sets):
    points, normals = _arrays(box_sets)
    assert all(t.fingers == FINGERS for t in box_sets)
    # On the surface: inside the box and on one face (the coordinate at its half extent).
    excess = np.abs(points) - HALF_BOX_M
    assert np.all(excess <= 1e-9)
    assert np.all(np.abs(excess.max(axis=2)) < 1e-6)
    # Each normal is the outward normal of a face the point lies on (either one on an edge).
    axis = np.argmax(np.abs(normals), axis=2)[..., None]
    np.testing.assert_allclose(np.abs(np.take_along_axis(normals, axis, 2)), 1.0, atol=1e-12)
    assert np.all(np.abs(np.take_along_axis(excess, axis, 2)) < 1e-6)
    same_side = np.sign(np.take_along_axis(points, axis, 2)) == np.take_along_axis(normals, axis, 2)
    assert same_side.all()
    assert np.all(np.abs(np.linalg.norm(normals, axis=2) - 1.0) < 1e-6)


def test_the_thumb_opposes_the_fingers_within_the_hands_reach(box_sets):
    points, normals = _arrays(box_sets)
    mean = normals[:, 1:].sum(axis=1)
    mean /= np.linalg.norm(mean, axis=1)[:, None]
    opposition = np.einsum("ij,ij->i", normals[:, 0], mean)
    assert np.all(opposition <= -math.cos(math.radians(SamplerSettings().opposition_deg)))
    lo, hi = SAH_REACH.finger_spacing_m
    for finger in (1, 3):
        spacing = np.linalg.norm(points[:, finger] - points[:, 2], axis=1)
        assert np.all((spacing >= lo) & (spacing <= hi))
    span = np.linalg.norm(points[:, 2] - points[:, 0], axis=1)
    assert np.all((span >= SAH_REACH.span_m[0]) & (span <= SAH_REACH.span_m[1]))


def test_cylinder_contacts_are_on_the_mesh_and_normals_point_out(cylinder):
    targets = sample_contact_sets(cylinder, 10, seed=102)
    triangles = cylinder.triangles
    points, normals = _arrays(targets)
    for point in points.reshape(-1, 3):
        assert _mesh_distance(triangles, point) < 1e-6
    # A step outward along the normal leaves the (convex) cylinder: it gets farther from the
    # axis or beyond a cap.
    probe = points + 1e-3 * normals
    radial = np.linalg.norm(probe[..., :2], axis=2)
    outside = (radial > np.linalg.norm(points[..., :2], axis=2) + 1e-4) | (
        np.abs(probe[..., 2]) > CYLINDER_HEIGHT_M / 2
    )
    assert outside.all()


def test_inward_wound_mesh_gives_the_same_outward_normals(cylinder):
    inward = (cylinder.vertices, cylinder.faces[:, ::-1])
    _, outward_normals = _arrays(sample_contact_sets(cylinder, 3, seed=103))
    _, flipped_normals = _arrays(sample_contact_sets(inward, 3, seed=103))
    np.testing.assert_allclose(flipped_normals, outward_normals, atol=1e-12)


def test_same_seed_same_sets_other_seed_other_sets(cylinder):
    first = sample_contact_sets(cylinder, 4, seed=104)
    assert sample_contact_sets(cylinder, 4, seed=104) == first
    assert sample_contact_sets(cylinder, 2, seed=104) == first[:2]
    other = sample_contact_sets(cylinder, 4, seed=105)
    assert all(a.contacts != b.contacts for a, b in zip(first, other, strict=True))


def test_catalog_object_contacts_are_on_its_exposed_surface():
    # The Buddha is assembled from overlapping solids: no contact may lie inside another one.
    obj = load_object("buddha")
    targets = sample_object_grasps(obj, 3, seed=106)
    points, normals = _arrays(targets)
    mesh = obj.mesh()
    triangles = mesh.vertices_m[mesh.faces]
    for point in points.reshape(-1, 3):
        assert _mesh_distance(triangles, point) < 1e-6
    # Within the pieces' chord error of the union's boundary, and outside it along the normal.
    depth = obj.signed_distance(points.reshape(-1, 3))
    assert np.all(np.abs(depth) < 2e-4)
    assert np.all(obj.signed_distance((points + 2e-3 * normals).reshape(-1, 3)) > 1e-3)


def test_no_contact_inside_another_shell_of_the_same_mesh():
    a = trimesh.creation.box((0.06, 0.06, 0.06))
    b = trimesh.creation.box((0.06, 0.06, 0.06))
    b.apply_translation((0.03, 0.03, 0.0))  # a quarter of each box lies inside the other
    union = (np.vstack([a.vertices, b.vertices]), np.vstack([a.faces, b.faces + len(a.vertices)]))
    points, _ = _arrays(sample_contact_sets(union, 20, seed=110))
    points = points.reshape(-1, 3)
    for centre in ((0.0, 0.0, 0.0), (0.03, 0.03, 0.0)):
        depth_inside = 0.03 - np.abs(points - centre).max(axis=1)
        assert np.all(depth_inside < 1e-9)


def test_object_placement_moves_the_contacts():
    shift = np.eye(4)
    shift[:3, 3] = [0.1, -0.2, 0.3]
    here = sample_object_grasps(load_object("can"), 2, seed=107)
    there = sample_object_grasps(load_object("can", shift), 2, seed=107)
    for a, b in zip(_arrays(here)[0], _arrays(there)[0], strict=True):
        np.testing.assert_allclose(b - a, np.tile(shift[:3, 3], (4, 1)), atol=1e-12)


@pytest.mark.parametrize(
    ("vertices", "faces", "message"),
    [
        (np.zeros((0, 3)), np.zeros((0, 3), int), "shape"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, np.nan]], [[0, 1, 2]] * 4, "NaN"),
        (np.eye(4, 3), [[0, 1, 7]] * 4, "indices"),
        ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], [[0, 1, 2], [1, 3, 2]] * 2, "volume"),
    ],
)
def test_malformed_meshes_get_a_typed_error(vertices, faces, message):
    with pytest.raises(GraspSamplingError, match=message):
        SurfaceMesh(vertices, faces)


def test_an_object_out_of_reach_is_a_typed_error_naming_the_rejections():
    huge = trimesh.creation.box((1.0, 1.0, 1.0))
    settings = SamplerSettings(max_attempts_per_set=5)
    with pytest.raises(SahGraspError, match="no_opposite"):
        sample_contact_sets(huge, 2, seed=108, settings=settings)


def test_bad_reach_and_settings_are_typed_errors():
    with pytest.raises(GraspSamplingError, match="span_m"):
        HandReach((0.03, 0.04), (0.2, 0.1), 0.01)
    with pytest.raises(GraspSamplingError, match="opposition_deg"):
        SamplerSettings(opposition_deg=120.0)
    with pytest.raises(GraspSamplingError, match="trimesh"):
        sample_contact_sets("a mesh", 1, seed=109)
    with pytest.raises(GraspSamplingError, match="count"):
        sample_contact_sets(trimesh.creation.box((0.05, 0.05, 0.05)), -1, seed=109)


def _plate_grasp(span_m: float, spacing_m: float) -> GraspTarget:
    """Thumb on one face of a plate, the fingers in a line on the other, normals along x."""
    x = span_m / 2.0
    return GraspTarget(
        "plate",
        [
            ContactTarget("thumb", [-x, 0, 0], [-1, 0, 0]),
            ContactTarget("index", [x, 0, spacing_m], [1, 0, 0]),
            ContactTarget("middle", [x, 0, 0], [1, 0, 0]),
            ContactTarget("ring", [x, 0, -spacing_m], [1, 0, 0]),
        ],
    )


def test_sah_reach_is_where_the_ik_stops_solving(sah: Hand):
    span_hi = SAH_REACH.span_m[1]
    spacing_lo, spacing_hi = SAH_REACH.finger_spacing_m
    assert solve_ik(sah, _plate_grasp(span_hi, spacing_hi)).success
    assert solve_ik(sah, _plate_grasp(SAH_REACH.span_m[0], spacing_lo)).success
    assert not solve_ik(sah, _plate_grasp(span_hi + 0.004, spacing_hi)).success
    assert not solve_ik(sah, _plate_grasp(0.06, spacing_lo - 0.002)).success


def test_the_old_reach_name_warns_and_is_the_default_hands() -> None:
    import sahgrasp.objects.grasp_sampler as sampler

    with pytest.warns(DeprecationWarning, match="SAH_REACH is deprecated"):
        old = sampler.SAH_REACH
    assert old == SAH_REACH == registered_reach()
