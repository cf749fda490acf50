"""Things drawn beside a hand: triangle meshes, objects, contact targets.

A contact target is drawn as in Claret & Suárez Fig. 6a: a disk at the contact point, in the
object's tangent plane, with a cylinder along the outward normal (the fingertip-sphere centre lies
on it at ``R`` from the point).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import meshcat.geometry as mg
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from sahgrasp.model.contacts import GraspTarget
from sahgrasp.objects import GraspObject
from sahgrasp.viz.colors import FINGER_COLORS, MARKER_COLOR, hex_color
from sahgrasp.viz.viewer import Viewer

__all__ = ["show_contacts", "show_mesh", "show_object"]

_Y = np.array([0.0, 1.0, 0.0])  # axis of meshcat's cylinders


def _material(rgba: Sequence[float]) -> mg.MeshPhongMaterial:
    opacity = float(rgba[3]) if len(rgba) > 3 else 1.0
    return mg.MeshPhongMaterial(color=hex_color(rgba), opacity=opacity)


def show_mesh(
    viewer: Viewer,
    path: str,
    vertices_m: ArrayLike,
    faces: ArrayLike,
    rgba: Sequence[float],
    T_world: ArrayLike | None = None,
) -> None:
    """Draw a triangle mesh.

    Args:
        viewer: The scene.
        path: Scene path of the mesh.
        vertices_m: Vertex positions [m], shape (N, 3).
        faces: Vertex indices of each triangle, shape (M, 3).
        rgba: Colour, components in [0, 1] (alpha < 1 is transparent).
        T_world: Placement of the mesh frame (4x4; identity if None).
    """
    node = viewer.meshcat[path]
    node.set_object(mg.TriangularMeshGeometry(vertices_m, faces), _material(rgba))
    node.set_transform(np.eye(4) if T_world is None else np.asarray(T_world, dtype=np.float64))


def show_object(viewer: Viewer, path: str, obj: GraspObject) -> None:
    """Draw an object's display mesh in its colour at its placement."""
    mesh = obj.mesh()
    show_mesh(viewer, path, mesh.vertices_m, mesh.faces, obj.rgba, obj.T_world_object)


def _along(axis: NDArray[np.float64], centre: NDArray[np.float64]) -> NDArray[np.float64]:
    """Placement of a meshcat cylinder (axis y) centred at ``centre`` with its axis on ``axis``."""
    T = np.eye(4)
    T[:3, :3] = pin.Quaternion.FromTwoVectors(_Y, axis).toRotationMatrix()
    T[:3, 3] = centre
    return T


def show_contacts(
    viewer: Viewer,
    path: str,
    target: GraspTarget,
    disk_radius_m: float = 0.006,
    normal_length_m: float = 0.02,
    colors: Mapping[str, Sequence[float]] | None = None,
) -> None:
    """Draw each contact as a disk at its point with a cylinder along its outward normal.

    Args:
        viewer: The scene.
        path: Scene path; contact ``f`` goes to ``path/f/disk`` and ``path/f/normal``.
        target: The contacts (world frame).
        disk_radius_m: Radius of the disks [m].
        normal_length_m: Length of the normal cylinders [m].
        colors: RGBA colour per finger (default :data:`~sahgrasp.viz.colors.FINGER_COLORS`;
            a hand's own: :func:`~sahgrasp.viz.colors.finger_colors`).
    """
    colors = FINGER_COLORS if colors is None else colors
    thickness = 0.08 * disk_radius_m
    for c in target.contacts:
        material = _material(colors.get(c.finger, MARKER_COLOR))
        disk = viewer.meshcat[f"{path}/{c.finger}/disk"]
        disk.set_object(mg.Cylinder(thickness, disk_radius_m), material)
        disk.set_transform(_along(c.normal, c.point))
        stick = viewer.meshcat[f"{path}/{c.finger}/normal"]
        stick.set_object(mg.Cylinder(normal_length_m, 0.12 * disk_radius_m), material)
        stick.set_transform(_along(c.normal, c.point + 0.5 * normal_length_m * c.normal))
