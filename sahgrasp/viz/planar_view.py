"""A planar grasp in a scene (atlas paper Fig. 8): fingers as chains of links, the object's circles.

The plane's ``(x, y)`` is drawn upright, as the scene's ``(x, z)``, so that the camera in front
(-y) sees the hand as the paper's figure does: palm at the bottom, fingers up.
"""

from __future__ import annotations

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from sahgrasp.objects import transform_points
from sahgrasp.viz.colors import hex_color
from sahgrasp.viz.viewer import Viewer, translation

__all__ = ["PALM_RGBA", "PHALANX_RGBA", "PLANAR_OBJECT_RGBA", "show_planar_grasp", "upright"]

PHALANX_RGBA = (0.8, 0.8, 0.82, 1.0)
"""Colour of the phalanges (the SAH's link grey)."""
PALM_RGBA = (0.35, 0.37, 0.4, 1.0)
"""Colour of the palm and the joints."""
PLANAR_OBJECT_RGBA = (0.2, 0.45, 0.85, 1.0)
"""Colour of the object's circles."""

_LINK_RADIUS_M = 0.004
_DISK_THICKNESS_M = 0.006
_Y = np.array([0.0, 1.0, 0.0])  # axis of meshcat's cylinders


def upright(points_2d: ArrayLike) -> NDArray[np.float64]:
    """Scene points (..., 3) of plane points (..., 2): ``(x, y) -> (x, 0, y)``."""
    p = np.asarray(points_2d, dtype=np.float64)
    return np.stack([p[..., 0], np.zeros(p.shape[:-1]), p[..., 1]], axis=-1)


def _material(rgba: tuple[float, float, float, float]) -> mg.MeshPhongMaterial:
    return mg.MeshPhongMaterial(color=hex_color(rgba))


def _segment(
    viewer: Viewer,
    path: str,
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    rgba: tuple[float, float, float, float],
) -> None:
    T = np.eye(4)
    T[:3, :3] = pin.Quaternion.FromTwoVectors(_Y, b - a).toRotationMatrix()
    T[:3, 3] = 0.5 * (a + b)
    node = viewer.meshcat[path]
    node.set_object(mg.Cylinder(float(np.linalg.norm(b - a)), _LINK_RADIUS_M), _material(rgba))
    node.set_transform(T)


def show_planar_grasp(
    viewer: Viewer,
    path: str,
    fingers: ArrayLike,
    circles: ArrayLike,
    radii: ArrayLike,
    T_scene: ArrayLike | None = None,
) -> NDArray[np.float64]:
    """Draw a planar hand (palm joining the finger bases) and the circles of its object.

    Args:
        viewer: The scene.
        path: Scene path of the grasp (``path/palm``, ``path/finger<i>/...``, ``path/circle<j>``).
        fingers: Per finger the chain base, joints, tip in the plane, (F, P, 2) [m].
        circles: Circle centres in the plane, (C, 2) [m].
        radii: Circle radii, (C,) [m].
        T_scene: Placement (4x4) of the grasp in the scene (identity if None).

    Returns:
        Points spanning the drawing in the scene, (N, 3) [m].
    """
    T = np.eye(4) if T_scene is None else np.asarray(T_scene, dtype=np.float64)
    viewer.meshcat[path].set_transform(T)
    chains = upright(fingers)
    bases = chains[:, 0]
    _segment(viewer, f"{path}/palm", bases[0], bases[-1], PALM_RGBA)
    for i, chain in enumerate(chains):
        for j in range(len(chain) - 1):
            _segment(viewer, f"{path}/finger{i}/phalanx{j}", chain[j], chain[j + 1], PHALANX_RGBA)
        for j, joint in enumerate(chain[:-1]):
            node = viewer.meshcat[f"{path}/finger{i}/joint{j}"]
            node.set_object(mg.Sphere(1.6 * _LINK_RADIUS_M), _material(PALM_RGBA))
            node.set_transform(translation(joint))
    centres = upright(circles)
    rims = []
    for j, (centre, radius) in enumerate(zip(centres, np.asarray(radii, dtype=float), strict=True)):
        node = viewer.meshcat[f"{path}/circle{j}"]
        node.set_object(mg.Cylinder(_DISK_THICKNESS_M, radius), _material(PLANAR_OBJECT_RGBA))
        node.set_transform(translation(centre))  # cylinder axis y: the disk lies in the plane
        rims.append(centre + radius * np.array([[1.0, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1]]))
    drawn = np.concatenate([chains.reshape(-1, 3), *rims])
    return transform_points(T, drawn)
