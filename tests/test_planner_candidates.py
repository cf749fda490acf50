"""The planner's draws: closest points and ray crossings of a mesh (NearestPoint)."""

from __future__ import annotations

import numpy as np
import trimesh

from sahgrasp.objects.grasp_sampler import SurfaceMesh
from sahgrasp.planner.candidates import NearestPoint


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
