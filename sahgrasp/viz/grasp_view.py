"""A grasp in a scene: the object, its contact targets and the hand, together under one path.

Everything of one grasp hangs under ``path``, whose transform ``T_scene`` moves the whole grasp, so
several grasps can stand side by side in one scene.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject, transform_points
from sahgrasp.viz.colors import finger_colors
from sahgrasp.viz.hand_view import HandView, visual_corners
from sahgrasp.viz.markers import show_contacts, show_object
from sahgrasp.viz.viewer import Viewer

__all__ = ["frame_grasp", "grasp_points", "show_grasp"]

_ELEVATION = 0.7  # camera rise per unit of horizontal distance (about 35 deg above the grasp)


def show_grasp(
    viewer: Viewer,
    path: str,
    hand: Hand,
    q: NDArray[np.float64],
    obj: GraspObject | None = None,
    target: GraspTarget | None = None,
    history: Sequence[NDArray[np.float64]] | None = None,
    T_scene: ArrayLike | None = None,
) -> HandView:
    """Draw a hand at ``q`` with the object it grasps and the contact targets.

    Args:
        viewer: The scene.
        path: Scene path of the grasp: ``path/object``, ``path/contacts``, ``path/hand``.
        hand: The hand model.
        q: The hand configuration (shown when no animation plays).
        obj: The object, drawn in its colour at its placement (world frame).
        target: Contact targets, drawn as disks with normal cylinders (world frame).
        history: Configurations to animate through before ``q`` (e.g. ``IKResult.history``).
        T_scene: Placement (4x4) of the whole grasp in the scene (identity if None).

    Returns:
        The hand's view.
    """
    viewer.meshcat[path].set_transform(np.eye(4) if T_scene is None else np.asarray(T_scene))
    if obj is not None:
        show_object(viewer, f"{path}/object", obj)
    if target is not None:
        colors = finger_colors(hand.description.name)
        show_contacts(viewer, f"{path}/contacts", target, colors=colors)
    view = HandView(viewer, hand, f"{path}/hand", q)
    if history:
        view.animate(history)
    return view


def grasp_points(
    hand: Hand, q: NDArray[np.float64], obj: GraspObject | None = None
) -> NDArray[np.float64]:
    """Points spanning a drawn grasp (world frame) [m].

    The corners of the hand's visual bounding boxes at ``q`` and the object's mesh vertices.
    """
    hand_points = visual_corners(hand, q)
    if obj is None:
        return hand_points
    return np.concatenate(
        [transform_points(obj.T_world_object, obj.mesh().vertices_m), hand_points]
    )


def frame_grasp(
    viewer: Viewer,
    hand: Hand,
    q: NDArray[np.float64],
    target: GraspTarget,
    obj: GraspObject | None = None,
    aspect: float = 1.0,
) -> None:
    """Aim the camera at a grasp (world frame) from the palm's side, the whole grasp in view.

    The camera stands beyond the contacts as seen from the wrist, raised by about 35 deg, so it
    looks at the inside of the hand (not the back of the palm) with the object in front of it.

    Args:
        viewer: The scene.
        hand: The hand model.
        q: Its configuration (the wrist position is ``q[:3]``).
        target: The contact targets the hand reaches.
        obj: The object, kept in view when given.
        aspect: Smallest width/height ratio of the window the view must fit.
    """
    centre = np.mean([c.point for c in target.contacts], axis=0)
    outward = centre - np.asarray(q[:3], dtype=np.float64)
    outward[2] = 0.0
    if np.linalg.norm(outward) < 1e-9:  # wrist straight above or below: look from the front
        outward = np.array([0.0, -1.0, 0.0])
    outward /= np.linalg.norm(outward)
    direction = outward + np.array([0.0, 0.0, _ELEVATION])
    viewer.frame(grasp_points(hand, q, obj), direction, aspect)
