"""The planner's collision pieces: a triangle's prism built from its known faces."""

from __future__ import annotations

import coal
import numpy as np

from sahgrasp.collision.shapes import convex_hull
from sahgrasp.planner.pieces import prism


def test_a_prism_is_the_hull_of_its_six_points() -> None:
    rng = np.random.default_rng(5)
    request = coal.DistanceRequest()
    for _ in range(5):
        triangle = rng.normal(scale=0.02, size=(3, 3))
        normal = np.cross(triangle[1] - triangle[0], triangle[2] - triangle[0])
        normal /= np.linalg.norm(normal)
        points = np.concatenate([triangle, triangle - 0.01 * normal])
        built, hull = prism(points), convex_hull(points)
        assert np.allclose(built.placement, hull.placement)
        assert built.bounding_radius_m == hull.bounding_radius_m
        place = [coal.Transform3s(np.eye(3), s.placement[:3, 3]) for s in (built, hull)]
        for _ in range(40):
            ball = coal.Sphere(0.004)
            at = coal.Transform3s(np.eye(3), rng.normal(scale=0.02, size=3))
            d = [
                coal.distance(s.geometry, T, ball, at, request, coal.DistanceResult())
                for s, T in zip((built, hull), place, strict=True)
            ]
            assert abs(d[0] - d[1]) <= 1e-12
