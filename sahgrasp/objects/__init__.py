"""Objects to grasp: exact surfaces, contact patches, display meshes, coal collision geometry.

The papers' objects and grasps are in :mod:`sahgrasp.objects.catalog`; the reusable geometry in
:mod:`~sahgrasp.objects.profiles` (planar profiles), :mod:`~sahgrasp.objects.surfaces`
(parametrised surfaces), :mod:`~sahgrasp.objects.patches` (contact regions of the atlas paper),
:mod:`~sahgrasp.objects.solids`, :mod:`~sahgrasp.objects.body` (an object) and its meshes and
collision shapes; :mod:`~sahgrasp.objects.mesh_file` reads objects from mesh files and
:mod:`~sahgrasp.objects.targets` reads and writes targets files and builds the objects they name.
The hand-object clearance (``CONTACT_ALLOWANCE_M``, ``Clearance``, ``HandObjectClearance``) is
:mod:`sahgrasp.collision.hand_object`'s, exported here too. Lengths in metres, angles in radians.

The names are loaded on first use: importing one module of the package (the IK imports
:mod:`~sahgrasp.objects.body`) does not load the mesh readers (trimesh).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sahgrasp.core.lazy import lazy_exports

if TYPE_CHECKING:
    from sahgrasp.collision.hand_object import (
        CONTACT_ALLOWANCE_M,
        Clearance,
        HandObjectClearance,
    )
    from sahgrasp.collision.shapes import (
        CollisionShape,
        convex_hull,
        signed_distances,
    )
    from sahgrasp.core.frames import (
        as_placement,
        placement,
        rotation_about,
        transform_points,
    )
    from sahgrasp.objects.body import (
        GraspObject,
    )
    from sahgrasp.objects.catalog import (
        CATALOG,
        GRASP_NAMES,
        OBJECT_NAMES,
        PAPER_IK_REPORT,
        CatalogEntry,
        IKReport,
        bottle_patches,
        can_patches,
        load_object,
        paper_grasp,
        register_object,
    )
    from sahgrasp.objects.mesh_file import (
        MeshFileError,
        MeshSolid,
        load_mesh,
    )
    from sahgrasp.objects.meshing import (
        Mesh,
        tessellate,
    )
    from sahgrasp.objects.patches import (
        ContactRegion,
        CurvePatch,
        FixedContact,
        GraspPatches,
        Patch,
    )
    from sahgrasp.objects.profiles import (
        Arc,
        Segment,
        rounded_polyline,
        sample_profile,
    )
    from sahgrasp.objects.solids import (
        BoxSolid,
        EllipsoidSolid,
        RevolvedSolid,
        Solid,
    )
    from sahgrasp.objects.surfaces import (
        EllipsoidSurface,
        RectangleSurface,
        RevolvedSurface,
        Surface,
        SurfaceJet,
    )
    from sahgrasp.objects.targets import (
        MAX_PATH_CHARS,
        QUATERNION_TOLERANCE,
        InvalidProblem,
        ObjectCache,
        TargetsFile,
        build_object,
        load_targets,
        object_spec,
        problem_from_dict,
        problem_from_json,
        problem_from_line,
        read_problems,
        read_targets_document,
        save_targets,
        targets_hand,
    )

_EXPORTS = {
    "sahgrasp.collision.shapes": (
        "CollisionShape",
        "convex_hull",
        "signed_distances",
    ),
    "sahgrasp.core.frames": (
        "as_placement",
        "placement",
        "rotation_about",
        "transform_points",
    ),
    "sahgrasp.objects.body": ("GraspObject",),
    "sahgrasp.objects.catalog": (
        "CATALOG",
        "GRASP_NAMES",
        "OBJECT_NAMES",
        "PAPER_IK_REPORT",
        "CatalogEntry",
        "IKReport",
        "bottle_patches",
        "can_patches",
        "load_object",
        "paper_grasp",
        "register_object",
    ),
    "sahgrasp.collision.hand_object": (
        "CONTACT_ALLOWANCE_M",
        "Clearance",
        "HandObjectClearance",
    ),
    "sahgrasp.objects.mesh_file": (
        "MeshFileError",
        "MeshSolid",
        "load_mesh",
    ),
    "sahgrasp.objects.meshing": (
        "Mesh",
        "tessellate",
    ),
    "sahgrasp.objects.patches": (
        "ContactRegion",
        "CurvePatch",
        "FixedContact",
        "GraspPatches",
        "Patch",
    ),
    "sahgrasp.objects.profiles": (
        "Arc",
        "Segment",
        "rounded_polyline",
        "sample_profile",
    ),
    "sahgrasp.objects.solids": (
        "BoxSolid",
        "EllipsoidSolid",
        "RevolvedSolid",
        "Solid",
    ),
    "sahgrasp.objects.surfaces": (
        "EllipsoidSurface",
        "RectangleSurface",
        "RevolvedSurface",
        "Surface",
        "SurfaceJet",
    ),
    "sahgrasp.objects.targets": (
        "MAX_PATH_CHARS",
        "QUATERNION_TOLERANCE",
        "InvalidProblem",
        "ObjectCache",
        "TargetsFile",
        "build_object",
        "load_targets",
        "object_spec",
        "problem_from_dict",
        "problem_from_json",
        "problem_from_line",
        "read_problems",
        "read_targets_document",
        "save_targets",
        "targets_hand",
    ),
}

__all__ = [
    "CATALOG",
    "CONTACT_ALLOWANCE_M",
    "GRASP_NAMES",
    "MAX_PATH_CHARS",
    "OBJECT_NAMES",
    "PAPER_IK_REPORT",
    "QUATERNION_TOLERANCE",
    "Arc",
    "BoxSolid",
    "CatalogEntry",
    "Clearance",
    "CollisionShape",
    "ContactRegion",
    "CurvePatch",
    "EllipsoidSolid",
    "EllipsoidSurface",
    "FixedContact",
    "GraspObject",
    "GraspPatches",
    "HandObjectClearance",
    "IKReport",
    "InvalidProblem",
    "Mesh",
    "MeshFileError",
    "MeshSolid",
    "ObjectCache",
    "Patch",
    "RectangleSurface",
    "RevolvedSolid",
    "RevolvedSurface",
    "Segment",
    "Solid",
    "Surface",
    "SurfaceJet",
    "TargetsFile",
    "as_placement",
    "bottle_patches",
    "build_object",
    "can_patches",
    "convex_hull",
    "load_mesh",
    "load_object",
    "load_targets",
    "object_spec",
    "paper_grasp",
    "placement",
    "problem_from_dict",
    "problem_from_json",
    "problem_from_line",
    "read_problems",
    "read_targets_document",
    "register_object",
    "rotation_about",
    "rounded_polyline",
    "sample_profile",
    "save_targets",
    "signed_distances",
    "targets_hand",
    "tessellate",
    "transform_points",
]


__getattr__, __dir__ = lazy_exports(__name__, globals(), _EXPORTS)
