"""A grasp in a scene: the object, its contact targets and the hand, together under one path.

Everything of one grasp hangs under ``path``, whose transform ``T_scene`` moves the whole grasp, so
several grasps can stand side by side in one scene.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.contacts import GraspTarget
from sahgrasp.hand import Hand
from sahgrasp.objects import GraspObject
from sahgrasp.viz.hand_view import HandView
from sahgrasp.viz.markers import show_contacts, show_object
from sahgrasp.viz.viewer import Viewer

__all__ = ["show_grasp"]


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
        show_contacts(viewer, f"{path}/contacts", target)
    view = HandView(viewer, hand, f"{path}/hand", q)
    if history:
        view.animate(history)
    return view
