"""The joined collision pieces: revolved slabs and merged mesh prisms (docs/methods/objects.md).

Each check compares the joined pieces with the pieces they replace (one per band sector, one
prism per triangle): every point inside the old pieces is inside the new ones, and the new ones
reach out of the solid by no more than the chord (revolved) or merge (mesh) tolerance.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np
import pytest
import trimesh
from numpy.typing import NDArray

from sahgrasp.collision.shapes import CollisionShape, signed_distances
from sahgrasp.objects import load_object, mesh_file
from sahgrasp.objects.mesh_file import MERGE_TOLERANCE_M, MeshSolid, load_mesh
from sahgrasp.objects.profiles import chord_count
from sahgrasp.objects.solids import COLLISION_SAGITTA_M, RevolvedSolid, _bands, _slabs

MESHES = Path(__file__).resolve().parents[1] / "examples" / "meshes"
IDENTITY = np.eye(4)


def _band_pieces(solid: RevolvedSolid) -> list[CollisionShape]:
    """The pieces before joining: every band cut into sectors at the solid's largest radius."""
    n_sectors = chord_count(solid._turn_rad, solid._max_radius_m, COLLISION_SAGITTA_M)
    angles = np.linspace(*solid.angle_range_rad, n_sectors + 1)
    return [
        solid._hull(band, angles[k : k + 2])
        for band in _bands(solid.profile)
        for k in range(n_sectors)
    ]


def _near_surface(solid: RevolvedSolid, count: int, seed: int) -> NDArray[np.float64]:
    """Points within 3 mm of the solid's display mesh, in the object frame."""
    mesh = solid.mesh()
    surface = trimesh.Trimesh(mesh.vertices_m, mesh.faces, process=False)
    points, faces = trimesh.sample.sample_surface(surface, count, seed=seed)
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-3e-3, 3e-3, (count, 1)) * surface.face_normals[faces]
    return np.asarray(points, dtype=np.float64) + offsets


@pytest.mark.parametrize(("name", "solid_name"), [("coffee_cup", "cup"), ("coffee_cup", "saucer")])
def test_slabs_hold_the_bands_and_stay_within_the_chords(name: str, solid_name: str) -> None:
    solid = next(s for s in load_object(name).solids if s.name == solid_name)
    assert isinstance(solid, RevolvedSolid)
    joined, bands = solid.collision_shapes(), _band_pieces(solid)
    assert len(joined) < len(bands) / 2
    points = _near_surface(solid, 400, seed=3)
    old = signed_distances(bands, IDENTITY, points)
    new = signed_distances(joined, IDENTITY, points)
    assert (old < 0).sum() > 50 and (old > 0).sum() > 50
    # Inside the band pieces: inside the slabs too. Inside a slab: within the chords' gap
    # (0.05 mm either piece, across the axis) of the band pieces.
    assert np.all(new[old < 0] < 1e-9)
    assert np.all(old[new < 0] < 2 * COLLISION_SAGITTA_M)


def test_slab_sections_are_convex_and_cover_the_bands() -> None:
    for obj_name in ("cup", "coffee_cup", "bottle", "can"):
        for solid in load_object(obj_name).solids:
            if not isinstance(solid, RevolvedSolid):
                continue
            bands = _bands(solid.profile)
            slabs = _slabs(bands)
            levels = np.concatenate([[bands[0][0, 1]], [b[1, 1] for b in bands]])
            joined_levels = np.concatenate([s[:, 1] for s in slabs])
            np.testing.assert_array_equal(np.unique(joined_levels), levels)
            for slab in slabs:
                ring = np.vstack([slab[:, 2:], slab[::-1, :2]])  # counter-clockwise in (r, z)
                edges = np.roll(ring, -1, axis=0) - ring
                turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1]
                turns -= edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
                lengths = np.linalg.norm(edges, axis=1) * np.linalg.norm(
                    np.roll(edges, -1, 0), axis=1
                )
                keep = lengths > 0
                assert np.all(turns[keep] / lengths[keep] > -1e-9), (obj_name, solid.name)


def test_the_can_is_one_convex_piece() -> None:
    """Its section is convex and on the axis: one solid of revolution, no sectors."""
    assert len(load_object("can").collision_shapes()) == 1


@functools.cache
def _mesh(name: str) -> MeshSolid:
    solid = load_mesh(MESHES / name).solids[0]
    assert isinstance(solid, MeshSolid)
    return solid


@pytest.mark.slow
@pytest.mark.parametrize("name", ["mug.stl", "bottle.obj"])
def test_merged_prisms_hold_every_prism_and_stay_in_the_mesh(name: str) -> None:
    solid = _mesh(name)
    pieces = solid.collision_shapes()
    assert len(pieces) < len(solid.faces) / 4
    corners = solid.vertices_m[solid.faces]
    depth = solid.wall_thickness_m()[:, None, None] * solid.trimesh.face_normals[:, None, :]
    rng = np.random.default_rng(5)
    chosen = rng.choice(len(corners), 150, replace=False)
    prism_points = np.concatenate([corners, corners - depth], axis=1)[chosen]
    # Each chosen prism's centroid and vertices, pulled 1 um towards the centroid.
    centroids = prism_points.mean(axis=1, keepdims=True)
    inner = (centroids + (1.0 - 1e-4) * (prism_points - centroids)).reshape(-1, 3)
    assert np.all(signed_distances(pieces, IDENTITY, inner) < 0.0)
    # The pieces' surfaces: outside the mesh by no more than the merge tolerance (+ EPA's).
    samples = np.vstack(
        [
            trimesh.sample.sample_surface(trimesh.convex.convex_hull(_points(p)), 30, seed=int(k))[
                0
            ]
            for k, p in enumerate(pieces)
        ]
    )
    inside = trimesh.proximity.signed_distance(solid.trimesh, samples)  # positive inside
    assert inside.min() > -(MERGE_TOLERANCE_M + 1e-5)


@pytest.mark.slow
def test_merging_is_deterministic() -> None:
    first = _mesh("bottle.obj").collision_shapes()
    again = load_mesh(MESHES / "bottle.obj").collision_shapes()
    assert len(first) == len(again)
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(_points(a), _points(b))


def _points(piece: CollisionShape) -> NDArray[np.float64]:
    return np.asarray(piece.geometry.points(), dtype=np.float64) + piece.placement[:3, 3]


@pytest.mark.slow
def test_the_mug_cavity_and_handle_gap_stay_empty() -> None:
    """Hulls across the cavity or the handle's gap are refused: those points stay outside."""
    pieces = _mesh("mug.stl").collision_shapes()
    cavity, gap = [0.0, 0.0, 0.05], [0.0, 0.052, 0.05]  # mid-cavity; between wall and handle
    assert np.all(signed_distances(pieces, IDENTITY, [cavity, gap]) > 5e-3)


def test_a_convex_mesh_is_its_hull(tmp_path: Path) -> None:
    path = tmp_path / "ball.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=0.04).export(path)
    solid = load_mesh(path).solids[0]
    assert isinstance(solid, MeshSolid) and len(solid.collision_shapes()) == 1


@pytest.mark.slow
def test_the_merge_budget_leaves_the_rest_as_single_prisms(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    full = len(_mesh("bottle.obj").collision_shapes())
    monkeypatch.setattr(mesh_file, "MERGE_BUDGET", 20_000)
    copy = tmp_path / "bottle.obj"  # another path: load_mesh keeps the shipped one's pieces
    copy.write_bytes((MESHES / "bottle.obj").read_bytes())
    solid = load_mesh(copy).solids[0]
    assert isinstance(solid, MeshSolid)
    pieces = solid.collision_shapes()
    assert full < len(pieces) < len(solid.faces)
    # Whatever the budget, every prism's centroid lies inside the pieces.
    corners = solid.vertices_m[solid.faces]
    depth = solid.wall_thickness_m()[:, None, None] * solid.trimesh.face_normals[:, None, :]
    centroids = np.concatenate([corners, corners - depth], axis=1).mean(axis=1)
    assert np.all(signed_distances(pieces, IDENTITY, centroids) < 0.0)


@pytest.mark.slow
def test_simulation_pieces_merge_further_where_the_budget_stopped(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    shipped = _mesh("bottle.obj")
    assert shipped.simulation_shapes() is shipped.collision_shapes()  # the merge completed
    full = len(shipped.collision_shapes())
    monkeypatch.setattr(mesh_file, "MERGE_BUDGET", 20_000)
    copy = tmp_path / "bottle.obj"
    copy.write_bytes((MESHES / "bottle.obj").read_bytes())
    solid = load_mesh(copy).solids[0]
    assert isinstance(solid, MeshSolid)
    simulated = solid.simulation_shapes()
    assert full <= len(simulated) < len(solid.collision_shapes())
    corners = solid.vertices_m[solid.faces]
    depth = solid.wall_thickness_m()[:, None, None] * solid.trimesh.face_normals[:, None, :]
    centroids = np.concatenate([corners, corners - depth], axis=1).mean(axis=1)
    assert np.all(signed_distances(simulated, IDENTITY, centroids) < 0.0)
