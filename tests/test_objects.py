import functools
import itertools
import math
import pickle
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from numpy.typing import NDArray

from sahgrasp.core.errors import InvalidTargetError
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.objects import (
    GRASP_NAMES,
    OBJECT_NAMES,
    PAPER_IK_REPORT,
    Arc,
    CollisionShape,
    ContactRegion,
    CurvePatch,
    GraspObject,
    GraspPatches,
    Patch,
    RevolvedSolid,
    RevolvedSurface,
    Segment,
    SurfaceJet,
    as_placement,
    bottle_patches,
    can_patches,
    load_object,
    paper_grasp,
    placement,
    rotation_about,
    rounded_polyline,
    signed_distances,
    transform_points,
)

CHORD_TOL_M = 2e-4  # collision pieces are within 0.1 mm of the exact surfaces
OFFSET_M = 1e-3
FRACTIONS = (0.1, 0.5, 0.9)
POSE = placement(rotation_about((0.3, -0.5, 0.8), 2.1), (0.4, -0.2, 0.7))
FINGERS = ("thumb", "index", "middle", "ring")


def _grid(lower: NDArray[np.float64], upper: NDArray[np.float64]) -> list[NDArray[np.float64]]:
    """Parameters at interior fractions of the box (every combination); no parameter: one point."""
    if len(lower) == 0:
        return [np.zeros(0)]
    axes = [lo + np.array(FRACTIONS) * (hi - lo) for lo, hi in zip(lower, upper, strict=True)]
    return [np.array(p) for p in np.stack(np.meshgrid(*axes), -1).reshape(-1, len(axes))]


def _samples(region: ContactRegion) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    jets = [region.evaluate(p) for p in _grid(region.lower, region.upper)]
    return np.array([j.point for j in jets]), np.array([j.normal for j in jets])


@pytest.fixture(scope="module", params=OBJECT_NAMES)
def obj(request: pytest.FixtureRequest) -> GraspObject:
    return load_object(request.param)


def test_names_and_paper_report() -> None:
    assert set(GRASP_NAMES) < set(OBJECT_NAMES)
    assert set(OBJECT_NAMES) == {"fork", "cup", "buddha", "coffee_cup", "can", "bottle"}
    assert PAPER_IK_REPORT == {
        "fork": (1, 6),
        "cup": (1, 13),
        "buddha": (3, 25),
        "coffee_cup": (7, 38),
        "can": (1, 22),
    }
    assert PAPER_IK_REPORT["buddha"].initial_configurations == 3
    assert PAPER_IK_REPORT["buddha"].jacobian_iterations == 25


@pytest.mark.parametrize(("loader", "name"), [(load_object, "spoon"), (paper_grasp, "bottle")])
def test_unknown_names_raise_typed_error(loader: Callable[[str], object], name: str) -> None:
    with pytest.raises(InvalidTargetError, match="valid names are") as info:
        loader(name)
    assert "can" in str(info.value)


def test_surfaces_lie_on_their_solid_with_outward_unit_normals(obj: GraspObject) -> None:
    """Each solid alone: points at ~0, outside offsets at ~+offset, inside balls negative."""
    for solid in obj.solids:
        shapes = solid.collision_shapes()
        for patch in solid.boundary():
            points, normals = _samples(patch)
            np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
            on = signed_distances(shapes, obj.T_world_object, points)
            out = signed_distances(shapes, obj.T_world_object, points + OFFSET_M * normals)
            inside = signed_distances(
                shapes, obj.T_world_object, points - 0.6e-3 * normals, probe_radius_m=0.3e-3
            )
            where = f"{obj.name}/{patch.name}"
            np.testing.assert_allclose(on, 0.0, atol=CHORD_TOL_M, err_msg=where)
            # Outside along the normal; nearer than the offset only in concave corners.
            assert np.all((out > 0.5 * OFFSET_M) & (out < OFFSET_M + CHORD_TOL_M)), where
            assert np.all(inside < -0.2e-3), where


def test_object_data_is_displayable_and_picklable(obj: GraspObject) -> None:
    mesh = obj.mesh()
    assert mesh.vertices_m.ndim == 2 and mesh.vertices_m.shape[1] == 3
    assert np.all(np.isfinite(mesh.vertices_m))
    assert mesh.faces.min() >= 0 and mesh.faces.max() < len(mesh.vertices_m)
    assert all(0.0 <= c <= 1.0 for c in obj.rgba)
    for solid in obj.solids:
        assert _volume_m3(solid.mesh().vertices_m, solid.mesh().faces) > 0.0, solid.name
    clone = pickle.loads(pickle.dumps(obj))
    np.testing.assert_array_equal(clone.mesh().vertices_m, mesh.vertices_m)


def _volume_m3(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> float:
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def test_can_is_a_330ml_drink_can() -> None:
    can = load_object("can", POSE)
    inside_outside = can.signed_distance(transform_points(POSE, [[0, 0, 0.05], [0, 0, 0.12]]))
    np.testing.assert_allclose(inside_outside, [-0.033, 0.005], atol=3e-4)  # EPA depth
    can = load_object("can")
    volume = _volume_m3(can.mesh().vertices_m, can.mesh().faces)
    assert 0.36e-3 < volume < 0.40e-3  # outer volume of a 330 ml can (headspace, metal)
    extent = np.ptp(can.mesh().vertices_m, axis=0)
    np.testing.assert_allclose(extent, [0.066, 0.066, 0.115], atol=1e-4)


@functools.cache
def _shapes(name: str) -> tuple[CollisionShape, ...]:
    return load_object(name).collision_shapes()


def _assert_on_exposed_surface(
    name: str, T: Any, points: NDArray[np.float64], normals: NDArray[np.float64]
) -> None:
    """Points on the object's (union) surface at placement ``T``, not inside another solid."""
    probes = np.concatenate([points, points + 2 * OFFSET_M * normals])
    on, out = np.split(signed_distances(_shapes(name), as_placement(T), probes), 2)
    np.testing.assert_allclose(on, 0.0, atol=CHORD_TOL_M)
    np.testing.assert_allclose(out, 2 * OFFSET_M, atol=CHORD_TOL_M)


@pytest.mark.parametrize("name", GRASP_NAMES)
def test_paper_grasps_touch_the_object(name: str) -> None:
    grasp = paper_grasp(name)
    assert isinstance(grasp, GraspTarget) and grasp.name == name
    grasp.check_fingers(FINGERS)
    points = np.array([grasp.contact(f).point for f in FINGERS])
    normals = np.array([grasp.contact(f).normal for f in FINGERS])
    _assert_on_exposed_surface(name, np.eye(4), points, normals)
    # Precision grasp: thumb against the middle finger, neighbours at finger spacing.
    assert normals[0] @ normals[2] < -0.5
    spacing = np.linalg.norm(np.diff(points[1:], axis=0), axis=1)
    assert np.all((spacing > 0.024) & (spacing < 0.045)), spacing


@pytest.mark.parametrize("name", GRASP_NAMES)
def test_paper_grasps_follow_the_object_placement(name: str) -> None:
    here, there = paper_grasp(name), paper_grasp(name, POSE)
    for a, b in zip(here.contacts, there.contacts, strict=True):
        np.testing.assert_allclose(b.point, POSE[:3, :3] @ a.point + POSE[:3, 3], atol=1e-12)
        np.testing.assert_allclose(b.normal, POSE[:3, :3] @ a.normal, atol=1e-12)
    points = np.array([c.point for c in there.contacts])
    normals = np.array([c.normal for c in there.contacts])
    _assert_on_exposed_surface(name, POSE, points, normals)


def _central_difference(
    region: ContactRegion, params: NDArray[np.float64], step: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    columns_p, columns_n = [], []
    for k in range(len(params)):
        delta = np.zeros(len(params))
        delta[k] = step
        plus, minus = region.evaluate(params + delta), region.evaluate(params - delta)
        columns_p.append((plus.point - minus.point) / (2 * step))
        columns_n.append((plus.normal - minus.normal) / (2 * step))
    return np.stack(columns_p, -1), np.stack(columns_n, -1)


def _regions() -> list[ContactRegion]:
    regions: list[ContactRegion] = [
        p for n in OBJECT_NAMES for p in load_object(n).surface_patches()
    ]
    for patches in (can_patches(POSE), bottle_patches(POSE)):
        regions.extend(patches.regions.values())
    return regions


def test_patch_derivatives_match_central_differences() -> None:
    for region in _regions():
        for params in _grid(region.lower, region.upper)[::2]:
            jet: SurfaceJet = region.evaluate(params)
            dim = len(params)
            assert jet.point_jacobian.shape == jet.normal_jacobian.shape == (3, dim)
            if dim == 0:
                continue
            fd_point, fd_normal = _central_difference(region, params, 1e-6)
            np.testing.assert_allclose(
                jet.point_jacobian, fd_point, rtol=1e-6, atol=1e-7, err_msg=region.name
            )
            np.testing.assert_allclose(
                jet.normal_jacobian, fd_normal, rtol=1e-6, atol=1e-5, err_msg=region.name
            )


def test_scalar_jets_equal_the_array_jets() -> None:
    """The scalar path (float u, v: plain math) gives the broadcast path's jet to 1e-12."""
    rng = np.random.default_rng(13)
    pieces = [
        Segment((0.033, 0.0), (0.033, 0.115)),
        Segment((0.01, 0.02), (0.04, 0.07)),
        Arc((0.02, 0.05), 0.01, 0.3, 1.2),
        Arc((0.02, 0.05), 0.015, 2.0, -1.5),
    ]
    for piece in pieces:
        surface = RevolvedSurface(piece)
        u = rng.uniform(-math.pi, math.pi, 200)
        v = rng.uniform(0.0, piece.length_m, 200)
        batch = surface.jet(u, v).transformed(POSE)
        for i in range(len(u)):
            for one in (surface.jet(u[i], v[i]).transformed(POSE), _placed(surface, u[i], v[i])):
                assert one.point_jacobian.shape == (3, 2)
                for got, want in zip(_fields(one), _fields(batch), strict=True):
                    np.testing.assert_allclose(got, want[i], rtol=0.0, atol=1e-12)
    curve = bottle_patches(POSE).regions["index"]
    assert isinstance(curve, CurvePatch)
    u = rng.uniform(*curve.u_range, 50)
    batch = curve.surface.jet(u, curve.v_fixed).transformed(curve.placement)
    for i in range(len(u)):
        one = curve.evaluate((u[i],))
        assert one.point_jacobian.shape == (3, 1)
        for got, want in zip(_fields(one), _fields(batch), strict=True):
            np.testing.assert_allclose(
                got, want[i][..., :1] if got.ndim == 2 else want[i], atol=1e-12
            )


def _placed(surface: RevolvedSurface, u: float, v: float) -> SurfaceJet:
    return Patch("p", surface, (-4.0, 4.0), (0.0, 1.0), (0.0, 0.0), POSE).evaluate((u, v))


def _fields(jet: SurfaceJet) -> tuple[NDArray[np.float64], ...]:
    return jet.point, jet.normal, jet.point_jacobian, jet.normal_jacobian


def test_patch_accessors_agree_with_evaluate() -> None:
    side = can_patches().regions["index"]
    top = bottle_patches().regions["index"]
    assert isinstance(side, Patch) and isinstance(top, CurvePatch)
    jet = side.evaluate((0.3, 0.05))
    np.testing.assert_array_equal(side.point(0.3, 0.05), jet.point)
    np.testing.assert_array_equal(side.normal(0.3, 0.05), jet.normal)
    np.testing.assert_array_equal(side.point_jacobian(0.3, 0.05), jet.point_jacobian)
    np.testing.assert_array_equal(side.normal_jacobian(0.3, 0.05), jet.normal_jacobian)
    np.testing.assert_allclose(side.point(0.0, 0.05), [0.033, 0.0, 0.05], atol=1e-15)
    np.testing.assert_array_equal(top.point(1.5), top.evaluate(1.5).point)
    np.testing.assert_array_equal(top.normal(1.5), top.evaluate(1.5).normal)
    assert top.point_jacobian(1.5).shape == top.normal_jacobian(1.5).shape == (3, 1)
    np.testing.assert_allclose(top.normal(math.pi / 2), [0, 0.5**0.5, 0.5**0.5], atol=1e-15)


@pytest.mark.parametrize(
    ("factory", "name", "fingers"),
    [
        (can_patches, "can", ("thumb", "index", "middle")),
        (bottle_patches, "bottle", ("index", "thumb", "middle")),
    ],
)
def test_atlas_patches_lie_on_the_object(
    factory: Callable[..., GraspPatches], name: str, fingers: tuple[str, ...]
) -> None:
    for pose in (np.eye(4), POSE):
        patches = factory(pose)
        assert tuple(patches.regions) == fingers
        for region in patches.regions.values():
            assert np.all(region.lower <= region.nominal) and np.all(region.nominal <= region.upper)
            _assert_on_exposed_surface(name, pose, *_samples(region))
        nominal = patches.target()
        assert nominal.fingers == fingers


def test_can_patches_cover_the_side_and_start_from_the_paper_grasp() -> None:
    patches = can_patches()
    side = patches.regions["index"]
    assert side.lower[0] == -math.pi and side.upper[0] == math.pi
    assert side.lower[1] < 0.015 and side.upper[1] > 0.095  # straight wall of a 115 mm can
    assert patches.regions["thumb"].lower.shape == (0,)
    grasp = paper_grasp("can")
    for contact in patches.target().contacts:
        np.testing.assert_allclose(contact.point, grasp.contact(contact.finger).point, atol=1e-12)
    moved = patches.target({"index": (0.5, 0.08)}).contact("index")
    np.testing.assert_allclose(moved.point, [0.033 * math.cos(0.5), 0.033 * math.sin(0.5), 0.08])
    with pytest.raises(InvalidTargetError, match="no region for finger"):
        patches.target({"ring": (0.0, 0.05)})


def test_fixed_contact_takes_no_parameter() -> None:
    with pytest.raises(ValueError, match="takes no parameter"):
        can_patches().regions["thumb"].evaluate((0.1,))


def test_rounded_polyline_is_tangent_continuous_and_checked() -> None:
    mm = 1e-3
    pieces = rounded_polyline(
        [(0, 0), (30 * mm, 0), (36 * mm, 90 * mm), (0, 90 * mm)], [3 * mm, 2 * mm]
    )
    assert [type(p) for p in pieces] == [Segment, Arc, Segment, Arc, Segment]
    for a, b in itertools.pairwise(pieces):
        end, tangent_end, _ = a.evaluate(a.length_m)
        start, tangent_start, _ = b.evaluate(0.0)
        np.testing.assert_allclose(end, start, atol=1e-12)
        np.testing.assert_allclose(tangent_end, tangent_start, atol=1e-12)
    with pytest.raises(ValueError, match="overlap"):
        rounded_polyline([(0, 0), (1 * mm, 0), (1 * mm, 1 * mm)], [5 * mm])
    with pytest.raises(ValueError, match="one radius per interior vertex"):
        rounded_polyline([(0, 0), (1 * mm, 0)], [1 * mm])


def test_profiles_crossing_a_level_twice_are_refused() -> None:
    mm = 1e-3
    hook = [
        (0, 0),
        (10 * mm, 0),
        (10 * mm, 10 * mm),
        (5 * mm, 10 * mm),
        (5 * mm, 5 * mm),
        (2 * mm, 5 * mm),
        (2 * mm, 12 * mm),
        (0, 12 * mm),
    ]
    solid = RevolvedSolid("hook", rounded_polyline(hook, [0.0] * 6))
    with pytest.raises(ValueError, match="more than once"):
        solid.collision_shapes()
