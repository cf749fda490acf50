"""A plan's best grasps side by side in one meshcat scene, each labelled with rank and quality.

Each grasp (hand, object, contact targets) is turned about its contacts' centre so that the
direction from its wrist to its contacts points at the camera (the camera looks into the palm,
as :func:`sahgrasp.viz.frame_grasp` does for one grasp), then set beside the previous one along
x in rows. A label above each grasp gives its rank, finger count, force closure and L1 epsilon.
"""

from __future__ import annotations

import io
import math
import os
from pathlib import Path

import meshcat.geometry as mg
import numpy as np
from numpy.typing import NDArray

from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand
from sahgrasp.objects.body import GraspObject
from sahgrasp.planner.plan import GraspPlan, PlannedGrasp
from sahgrasp.viz.grasp_view import grasp_points, show_grasp
from sahgrasp.viz.viewer import Viewer

__all__ = ["draw_plan", "plan_scene", "write_plan_html"]

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


def plan_scene(hand: Hand, obj: GraspObject, plan: GraspPlan, count: int = _MAX_SHOWN) -> Viewer:
    """The scene (an offline :class:`sahgrasp.viz.Viewer`) of the plan's first ``count`` grasps."""
    viewer = Viewer(title=f"sahgrasp plan: {obj.name}")
    draw_plan(viewer, hand, obj, plan, count)
    return viewer


def draw_plan(
    viewer: Viewer, hand: Hand, obj: GraspObject, plan: GraspPlan, count: int = _MAX_SHOWN
) -> None:
    """Draw the plan's first ``count`` grasps side by side into ``viewer`` (module docstring)."""
    grasps = plan.grasps[:count]
    columns = max(1, math.ceil(math.sqrt(1.8 * len(grasps))))
    turned = []
    for grasp in grasps:
        centre = np.mean([c.point for c in grasp.contacts], axis=0)
        outward = centre - grasp.q[:3]
        outward /= max(float(np.linalg.norm(outward)), 1e-12)
        R = _rotation_to(outward, _TOWARDS_CAMERA)
        turned.append((centre, R, (grasp_points(hand, grasp.q, obj) - centre) @ R.T))
    cell_x = max(float(np.ptp(p[:, 0])) for _, _, p in turned) + _GAP_M if turned else 0.0
    cell_z = (
        max(float(np.ptp(p[:, 2])) for _, _, p in turned) + 3 * _LABEL_HEIGHT_M if turned else 0.0
    )
    everything = []
    for rank, (grasp, (centre, R, points)) in enumerate(zip(grasps, turned, strict=True), 1):
        row, column = divmod(rank - 1, columns)
        mid = 0.5 * (points.min(axis=0) + points.max(axis=0))
        shift = np.array([column * cell_x - mid[0], 0.0, -row * cell_z - mid[2]])
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = shift - R @ centre
        target = GraspTarget(f"#{rank}", grasp.contacts)
        show_grasp(viewer, f"plan/{rank}", hand, grasp.q, obj, target, T_scene=T)
        placed = points + shift
        width = max(float(np.ptp(placed[:, 0])), 0.08)
        height = width * 96 / 512
        node = viewer.meshcat[f"labels/{rank}"]
        texture = mg.ImageTexture(image=mg.PngImage(_label_png(_label(grasp, rank))))
        node.set_object(mg.Box([width, 1e-4, height]), mg.MeshBasicMaterial(map=texture))
        T_label = np.eye(4)
        T_label[:3, 3] = [
            column * cell_x,
            placed[:, 1].min() - 0.01,
            placed[:, 2].max() + 0.5 * _LABEL_HEIGHT_M + 0.5 * height,
        ]
        node.set_transform(T_label)
        everything += [placed, T_label[:3, 3][None]]
    if everything:
        viewer.frame(np.concatenate(everything), np.array([0.0, -1.0, 0.25]), 1.2)


def write_plan_html(
    hand: Hand, obj: GraspObject, plan: GraspPlan, path: str | os.PathLike[str]
) -> Path:
    """Write :func:`plan_scene` as a standalone HTML file (atomically); returns the path."""
    return plan_scene(hand, obj, plan).save_html(path)
