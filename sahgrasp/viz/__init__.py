"""Meshcat scenes of hands, objects, contacts, IK iterates and atlases, exported as HTML.

:class:`Viewer` is a scene, recorded offline (no server) or served live by meshcat; every scene
exports as one standalone HTML file. :class:`HandView` draws a hand (its URDF visuals) at a
configuration or animated through IK iterates; :func:`show_grasp` adds the object and the contact
targets; :func:`show_atlas` colours an atlas's chart centres by a quality index and
:func:`show_atlas_grasps` adds the best and worst grasps. :mod:`sahgrasp.viz.paper_examples` solves
and shows the IK paper's examples (``examples/grasp_*.py``, ``sahgrasp demo``).
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
    hex_color,
    quality_colors,
)
from sahgrasp.viz.grasp_view import frame_grasp, grasp_points, show_grasp
from sahgrasp.viz.hand_view import HandView, visual_model
from sahgrasp.viz.markers import show_contacts, show_mesh, show_object
from sahgrasp.viz.paper_examples import (
    EXAMPLE_GAP_M,
    EXAMPLE_NAMES,
    ROW_ASPECT,
    GraspExample,
    add_ik_arguments,
    format_report,
    ik_settings,
    run_grasp_example,
    show_examples,
    solve_example,
)
from sahgrasp.viz.present import add_html_argument, present
from sahgrasp.viz.recording import RecordingWindow, scene_commands
from sahgrasp.viz.viewer import CAMERA_FOV_DEG, Viewer, ViewerError, translation

__all__ = [
    "ATLAS_SIZE_M",
    "CAMERA_FOV_DEG",
    "EXAMPLE_GAP_M",
    "EXAMPLE_NAMES",
    "FINGER_COLORS",
    "MARKER_COLOR",
    "QUALITY_COLORMAP",
    "ROW_ASPECT",
    "AtlasPlot",
    "ChartGrasp",
    "DrawExtreme",
    "GraspExample",
    "HandView",
    "RecordingWindow",
    "Viewer",
    "ViewerError",
    "add_html_argument",
    "add_ik_arguments",
    "display_points",
    "format_report",
    "frame_grasp",
    "grasp_points",
    "hex_color",
    "ik_settings",
    "present",
    "quality_colors",
    "run_grasp_example",
    "scene_commands",
    "show_atlas",
    "show_atlas_grasps",
    "show_atlas_scene",
    "show_contacts",
    "show_examples",
    "show_grasp",
    "show_mesh",
    "show_object",
    "solve_example",
    "translation",
    "visual_model",
]
