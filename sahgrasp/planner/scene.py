"""A plan's best grasps side by side in one meshcat scene, each labelled with rank and quality.

Each grasp (hand, object, contact targets) is turned about its contacts' centre so that the
direction from its wrist to its contacts points at the camera (the camera looks into the palm,
as :func:`sahgrasp.viz.frame_grasp` does for one grasp), then set beside the previous one along
x. A label above each grasp gives its rank, finger count, force closure and L1 epsilon.
"""

from __future__ import annotations

import io
import os
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
from numpy.typing import NDArray

from sahgrasp.contacts import GraspTarget
from sahgrasp.hand import Hand
from sahgrasp.objects.body import GraspObject
from sahgrasp.planner.plan import GraspPlan, PlannedGrasp

__all__ = ["plan_scene", "write_plan_html"]

FloatArray = NDArray[np.float64]

_TOWARDS_CAMERA = np.array([0.0, -1.0, 0.0])
"""Every grasp's wrist-to-contacts direction is turned to this one, the camera's side."""
_GAP_M = 0.05
"""Space between neighbouring grasps [m]."""
_LABEL_HEIGHT_M = 0.03
_MAX_SHOWN = 12


def _rotation_to(a: FloatArray, b: FloatArray) -> FloatArray:
    """The smallest rotation taking unit vector ``a`` to unit vector ``b``."""
    v, c = np.cross(a, b), float(a @ b)
    if c < -1.0 + 1e-9:  # opposite: half a turn about any axis normal to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    skew = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + skew + skew @ skew / (1.0 + c)


def _label_png(text: str) -> bytes:
    from PIL import Image, ImageDraw, ImageFont

    image = Image.new("RGB", (512, 96), (255, 255, 255))
    draw = ImageDraw.Draw(image)
    try:
        font: ImageFont.FreeTypeFont | ImageFont.ImageFont = ImageFont.load_default(size=44)
    except TypeError:  # Pillow < 10.1: a fixed bitmap font
        font = ImageFont.load_default()
    draw.text((14, 18), text, fill=(20, 20, 20), font=font)
    out = io.BytesIO()
    image.save(out, format="PNG")
    return out.getvalue()


def _label(grasp: PlannedGrasp, rank: int) -> str:
    q = grasp.quality
    closure = "FC" if q["force_closure"] else "no FC"
    return f"#{rank} {len(grasp.fingers)}f {closure} eps {q['epsilon_l1']:.3f}"


def plan_scene(hand: Hand, obj: GraspObject, plan: GraspPlan, count: int = _MAX_SHOWN) -> object:
    """The scene (:class:`sahgrasp.viz.Viewer`, offline) of the plan's first ``count`` grasps."""
    from sahgrasp.viz import Viewer, grasp_points, show_grasp

    viewer = Viewer(title=f"sahgrasp plan: {obj.name}")
    grasps = plan.grasps[:count]
    offset_x = 0.0
    everything = []
    for rank, grasp in enumerate(grasps, start=1):
        target = GraspTarget(f"#{rank}", grasp.contacts)
        centre = np.mean([c.point for c in grasp.contacts], axis=0)
        outward = centre - grasp.q[:3]
        outward /= max(float(np.linalg.norm(outward)), 1e-12)
        R = _rotation_to(outward, _TOWARDS_CAMERA)
        points = (grasp_points(hand, grasp.q, obj) - centre) @ R.T
        shift = np.array([offset_x - points[:, 0].min(), 0.0, 0.0])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = shift - R @ centre
        show_grasp(viewer, f"plan/{rank}", hand, grasp.q, obj, target, T_scene=T)
        placed = points + shift
        everything.append(placed)
        top = placed[:, 2].max() + 0.6 * _LABEL_HEIGHT_M
        width = max(float(np.ptp(placed[:, 0])), 0.08)
        node = viewer.meshcat[f"labels/{rank}"]
        texture = mg.ImageTexture(image=mg.PngImage(_label_png(_label(grasp, rank))))
        node.set_object(mg.Box([width, 1e-4, width * 96 / 512]),
                        mg.MeshBasicMaterial(map=texture))  # fmt: skip
        T_label = np.eye(4)
        T_label[:3, 3] = [0.5 * (placed[:, 0].min() + placed[:, 0].max()),
                          placed[:, 1].min() - 0.01, top + 0.5 * width * 96 / 512]  # fmt: skip
        node.set_transform(T_label)
        offset_x = placed[:, 0].max() + _GAP_M
    if everything:
        viewer.frame(np.concatenate(everything), np.array([0.0, -1.0, 0.35]), 16 / 9)
    return viewer


def write_plan_html(
    hand: Hand, obj: GraspObject, plan: GraspPlan, path: str | os.PathLike[str]
) -> Path:
    """Write :func:`plan_scene` as a standalone HTML file (atomically); returns the path."""
    viewer = plan_scene(hand, obj, plan)
    return viewer.save_html(path)  # type: ignore[attr-defined,no-any-return]
