"""The planner's draws: closest points and ray crossings of a mesh (NearestPoint), room tests."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np
import trimesh

from sahgrasp.model.hand import load_hand
from sahgrasp.objects.grasp_sampler import SurfaceMesh
from sahgrasp.planner.candidates import (
    Candidate,
    CandidateDraw,
    NearestPoint,
    ObjectFrame,
    finger_set,
    hand_reach,
)


def _meshes() -> list[trimesh.Trimesh]:
    c = trimesh.creation
    return [
        c.box(extents=(0.05, 0.07, 0.09)),  # few large faces
        c.cone(radius=0.04, height=0.1, sections=32),  # fans of faces sharing a corner
        c.torus(major_radius=0.045, minor_radius=0.015, major_sections=24, minor_sections=12),
        c.icosphere(subdivisions=3, radius=0.04),  # more faces than the k-d tree threshold
    ]


def test_closest_points_and_ray_crossings_match_the_surface_mesh() -> None:
    rng = np.random.default_rng(3)
    for mesh in _meshes():
        surface = SurfaceMesh(mesh.vertices, mesh.faces)
        nearest = NearestPoint(surface.triangles, surface.normals)
        for _ in range(150):
            point, normal = surface.sample_point(rng)
            query = point + rng.uniform(-0.004, 0.012) * normal + rng.normal(scale=0.01, size=3)
            found, face, distance = nearest.closest(query)
            _, _, expected = surface.closest(query)
            assert abs(distance - expected) <= 1e-12
            assert abs(np.linalg.norm(found - query) - distance) <= 1e-12
            # The point lies on its face's plane.
            assert abs(surface.normals[face] @ (found - surface.triangles[face, 0])) <= 1e-12
            direction = -normal + rng.normal(scale=0.3, size=3)
            direction /= np.linalg.norm(direction)
            t, faces = nearest.ray_hits(point, direction)
            t_ref, faces_ref = surface.ray_hits(point, direction)
            assert np.array_equal(faces, faces_ref)
            assert np.allclose(t, t_ref, rtol=0.0, atol=1e-15)


def _candidates(mesh: trimesh.Trimesh, draws: int) -> tuple[list[Candidate], Counter[str]]:
    """The candidates and rejections of ``draws`` draws on ``mesh`` for the SAH."""
    hand = load_hand("sah")
    surface = SurfaceMesh(mesh.vertices, mesh.faces)
    frame = ObjectFrame.of(
        surface.triangles.reshape(-1, 3), np.arange(3 * len(surface)).reshape(-1, 3)
    )
    draw = CandidateDraw(surface, hand_reach(hand), frame, 0.5)
    sets = [finger_set(hand, k) for k in (2, 3, 4)]
    found, rejected = [], Counter[str]()
    for i in range(draws):
        out = draw.draw(sets[i % 3], i)
        if isinstance(out, str):
            rejected[out] += 1
        else:
            found.append(out)
    return found, rejected


def test_no_candidate_touches_the_inside_of_a_narrow_tube() -> None:
    # Inner radius 20 mm: the normal of the inner wall meets the opposite wall within 40 mm.
    tube = trimesh.creation.annulus(r_min=0.02, r_max=0.035, height=0.06, sections=48)
    found, rejected = _candidates(tube, 300)
    assert rejected["cavity"] > 0 and found
    for candidate in found:
        radial = np.linalg.norm(candidate.points_m[:, :2], axis=1)
        inward = np.einsum("ij,ij->i", candidate.normals[:, :2], candidate.points_m[:, :2]) < 0
        assert not np.any(inward & (radial < 0.021))


def test_no_candidate_touches_the_floor_inside_the_mug() -> None:
    # The mug's inner floor is 92 mm below its rim: no fingertip there leaves its hull in 40 mm.
    mug = trimesh.load(Path(__file__).parents[1] / "examples" / "meshes" / "mug.stl")
    found, rejected = _candidates(mug, 400)
    assert rejected["deep"] > 0 and found
    floor = min(
        p[2] for c in found for p, n in zip(c.points_m, c.normals, strict=True) if n[2] > 0.9
    )  # the rim's top, where a fingertip touching from above has room
    assert floor > 0.09
