"""Meshcat scenes of hands, objects, contacts, IK iterates and atlases, exported as HTML.

:class:`Viewer` is a scene, recorded offline (no server) or served live by meshcat; every scene
exports as one standalone HTML file. :class:`HandView` draws a hand (its URDF visuals) at a
configuration or animated through IK iterates; :func:`show_grasp` adds the object and the contact
targets; :func:`show_atlas` colours an atlas's chart centres by a quality index and
:func:`show_atlas_grasps` adds the best and worst grasps; :func:`present` shows a scene live or
writes it. Drawing only: the papers' examples that use it are in :mod:`sahgrasp.experiments`.
"""

from sahgrasp.viz.atlas_view import (
    ATLAS_SIZE_M,
    AtlasPlot,
    ChartGrasp,
    DrawExtreme,
    display_points,
    show_atlas,
    show_atlas_grasps,
    show_atlas_scene,
)
from sahgrasp.viz.colors import (
    FINGER_COLORS,
    MARKER_COLOR,
    QUALITY_COLORMAP,
    RDYLGN_RGB,
    finger_colors,
    hex_color,
    quality_colormap,
    quality_colors,
)
from sahgrasp.viz.grasp_view import frame_grasp, grasp_points, show_grasp
from sahgrasp.viz.hand_view import HandView, visual_model
from sahgrasp.viz.markers import show_contacts, show_mesh, show_object
from sahgrasp.viz.present import present
from sahgrasp.viz.recording import RecordingWindow, scene_commands
from sahgrasp.viz.viewer import CAMERA_FOV_DEG, Viewer, ViewerError, translation

__all__ = [
    "ATLAS_SIZE_M",
    "CAMERA_FOV_DEG",
    "FINGER_COLORS",
    "MARKER_COLOR",
    "QUALITY_COLORMAP",
    "RDYLGN_RGB",
    "AtlasPlot",
    "ChartGrasp",
    "DrawExtreme",
    "HandView",
    "RecordingWindow",
    "Viewer",
    "ViewerError",
    "display_points",
    "finger_colors",
    "frame_grasp",
    "grasp_points",
    "hex_color",
    "present",
    "quality_colormap",
    "quality_colors",
    "scene_commands",
    "show_atlas",
    "show_atlas_grasps",
    "show_atlas_scene",
    "show_contacts",
    "show_grasp",
    "show_mesh",
    "show_object",
    "translation",
    "visual_model",
]
