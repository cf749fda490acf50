"""A hand's visual model in a scene: shown at a configuration, or animated through iterates.

The visual geometry is the URDF's (``pin.buildGeomFromUrdf(..., GeometryType.VISUAL, ...)`` on the
hand's own model, so configurations with the virtual contact joints apply unchanged): primitives
for the SAH, STL meshes for the Allegro hand. Pinocchio's ``MeshcatVisualizer`` draws it.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from pinocchio.visualize import MeshcatVisualizer

from sahgrasp.core.errors import HandModelError
from sahgrasp.model.hand import Hand
from sahgrasp.viz.viewer import Viewer

__all__ = ["HandView", "visual_corners", "visual_model"]

_VISUAL = pin.GeometryType.VISUAL


def visual_model(hand: Hand) -> pin.GeometryModel:
    """The URDF's visual geometry attached to ``hand.model``.

    Raises:
        HandModelError: The URDF's visual geometry does not load (e.g. a mesh file is missing).
    """
    d = hand.description
    dirs = [str(p) for p in d.package_dirs]
    try:
        return pin.buildGeomFromUrdf(hand.model, str(d.urdf_path), _VISUAL, None, dirs)
    except (ValueError, RuntimeError, OSError) as exc:
        raise HandModelError(f"visual geometry of {d.urdf_path} does not load: {exc}") from exc


def visual_corners(
    hand: Hand, q: NDArray[np.float64], visual: pin.GeometryModel | None = None
) -> NDArray[np.float64]:
    """Corners of every visual geometry's bounding box at ``q`` (8 per geometry, world frame) [m].

    Args:
        hand: The hand model.
        q: Its configuration.
        visual: Its visual model (:func:`visual_model` if None).
    """
    visual = visual_model(hand) if visual is None else visual
    data, visual_data = hand.model.createData(), visual.createData()
    pin.forwardKinematics(hand.model, data, hand.check_q(q))
    pin.updateGeometryPlacements(hand.model, data, visual, visual_data)
    corners = []
    for geometry, placement in zip(visual.geometryObjects, visual_data.oMg, strict=True):
        geometry.geometry.computeLocalAABB()
        box = geometry.geometry.aabb_local
        local = np.array(list(itertools.product(*zip(box.min_, box.max_, strict=True))))
        corners.append(local @ placement.rotation.T + placement.translation)
    return np.concatenate(corners)


class HandView:
    """One hand drawn under ``path`` of a viewer.

    Args:
        viewer: The scene.
        hand: The hand model.
        path: Scene path of the hand (e.g. ``"grasps/can/hand"``); a parent's transform moves it.
        q: Configuration to show first (the middle of every joint range if None).
    """

    def __init__(
        self, viewer: Viewer, hand: Hand, path: str = "hand", q: NDArray[np.float64] | None = None
    ) -> None:
        self.hand = hand
        self.path = path
        self._viewer = viewer
        self._visual = visual_model(hand)
        self._data = hand.model.createData()
        self._visual_data = self._visual.createData()
        self._viz = MeshcatVisualizer(hand.model, None, self._visual)
        self._viz.initViewer(viewer=viewer.meshcat)
        self._viz.loadViewerModel(rootNodeName=path)
        self.show(hand.configuration() if q is None else q)

    @property
    def node_names(self) -> tuple[str, ...]:
        """Scene paths of the hand's visual geometries, relative to the scene root."""
        return tuple(self._viz.getViewerNodeName(g, _VISUAL) for g in self._visual.geometryObjects)

    def show(self, q: NDArray[np.float64]) -> None:
        """Place the hand at configuration ``q``."""
        self._viz.display(self.hand.check_q(q))

    def placements(self, q: NDArray[np.float64]) -> list[NDArray[np.float64]]:
        """Placements (4x4) of the visual geometries at ``q`` (world frame of the hand)."""
        pin.forwardKinematics(self.hand.model, self._data, self.hand.check_q(q))
        pin.updateGeometryPlacements(self.hand.model, self._data, self._visual, self._visual_data)
        return [np.array(M.homogeneous) for M in self._visual_data.oMg]

    def animate(self, configurations: Sequence[NDArray[np.float64]]) -> None:
        """Animate the hand through ``configurations``, one keyframe each from keyframe 0.

        The hand stays where :meth:`show` put it when the animation is not playing.

        Args:
            configurations: E.g. ``IKResult.history``, the initial configuration first.
        """
        if not configurations:
            raise ValueError("nothing to animate: no configurations given")
        for frame, q in enumerate(configurations):
            key = self._viewer.keyframe(frame)
            for name, T in zip(self.node_names, self.placements(q), strict=True):
                key[name].set_transform(T)
        self._viewer.play()
