"""Write ``urdf/sah_right.urdf`` from the SAH's public fact sheet (docs/methods/hand-model.md).

The fact sheet gives millimetres and degrees in a modified-DH description; this script is the single
place where those numbers become the URDF (metres, radians). Run it from the repository root:
``python tools/make_sah_urdf.py``. Collision shapes are boxes, cylinders and spheres (URDF
primitives that Pinocchio, coal and yourdfpy all read), sized so that the open hand and the hand
closed without abduction are collision-free while neighbouring fingers abducted towards each other
collide (see docs/methods/hand-model.md).
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

MM = 1e-3
DEG = math.pi / 180.0
FINGERS = ("thumb", "index", "middle", "ring")

# Placement of each finger's abduction frame: parent link, translation [mm], axis, angle [deg].
ABDUCTION_FRAMES = {
    "thumb": ("thumb_base", (-6.0, 86.9, 97.0), (0.419, -0.419, 0.805), 102.31),
    "index": ("palm", (-4.3, 40.165, 145.43), (0.707, 0.0125, 0.707), 178.5623),
    "middle": ("palm", (-4.3, 0.0, 150.143), (0.707, 0.0, 0.707), 180.0),
    "ring": ("palm", (-4.3, -40.165, 145.43), (0.707, -0.0121, 0.707), 181.3898),
}
THUMB_BASE_ORIGIN_MM = (-3.0, 27.1, 0.0)
PROXIMAL_LENGTH_MM = 67.8
MIDDLE_LENGTH_MM = 30.0
TIP_CENTRE_MM = 29.5  # along the distal phalanx (+y) from the distal joint axis
TIP_RADIUS_MM = 10.0
LIMITS_DEG = {"j0": (-90.0, 0.0), "j1": (-15.0, 15.0), "j2": (-75.0, 4.0), "j3": (-75.0, -4.0)}

# Collision/visual primitives per link kind, in link frames [mm]: (kind, centre, size, rpy [rad]).
# box size = full extents; cylinder size = (radius, length); sphere size = (radius,).
SHAPES = {
    "palm": [("box", (-11.85, 0.0, 65.0), (65.7, 120.0, 130.0), (0, 0, 0))],
    "thumb_base": [("box", (-0.5, 33.0, 47.0), (47.0, 84.0, 92.0), (0, 0, 0))],
    "base": [("cylinder", (0.0, 0.0, 0.0), (18.0, 25.0), (math.pi / 2, 0, 0))],
    "proximal": [("box", (32.6, 0.0, 0.0), (58.4, 26.0, 30.0), (0, 0, 0))],
    "middle": [("box", (10.0, 0.0, 0.0), (36.0, 24.0, 28.0), (0, 0, 0))],
    "distal": [("box", (0.0, 8.0, 0.0), (22.0, 30.0, 26.0), (0, 0, 0))],
    "tip": [("sphere", (0.0, 0.0, 0.0), (TIP_RADIUS_MM,), (0, 0, 0))],
}
COLOURS = {
    "palm": "0.35 0.37 0.40 1",
    "thumb_base": "0.35 0.37 0.40 1",
    "base": "0.55 0.57 0.60 1",
    "proximal": "0.80 0.80 0.82 1",
    "middle": "0.80 0.80 0.82 1",
    "distal": "0.80 0.80 0.82 1",
    "tip": "0.20 0.45 0.85 1",
}


def fmt(values: tuple[float, ...] | np.ndarray, scale: float = 1.0) -> str:
    return " ".join(f"{v * scale:.9g}" for v in values)


def origin(xyz_mm: tuple[float, ...], rpy: tuple[float, ...] | np.ndarray = (0, 0, 0)) -> str:
    return f'<origin xyz="{fmt(xyz_mm, MM)}" rpy="{fmt(tuple(rpy))}"/>'


def geometry(kind: str, size: tuple[float, ...]) -> str:
    if kind == "box":
        return f'<box size="{fmt(size, MM)}"/>'
    if kind == "cylinder":
        return f'<cylinder radius="{size[0] * MM:.9g}" length="{size[1] * MM:.9g}"/>'
    return f'<sphere radius="{size[0] * MM:.9g}"/>'


def link(name: str, kind: str) -> str:
    parts = [f'  <link name="{name}">']
    for shape, centre, size, rpy in SHAPES[kind]:
        geo = geometry(shape, size)
        parts.append(
            f"    <visual>{origin(centre, rpy)}<geometry>{geo}</geometry>"
            f'<material name="{kind}"><color rgba="{COLOURS[kind]}"/></material></visual>'
        )
        parts.append(f"    <collision>{origin(centre, rpy)}<geometry>{geo}</geometry></collision>")
    parts.append(
        '    <inertial><mass value="0.05"/><inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5"'
        ' iyz="0" izz="1e-5"/></inertial>'
    )
    parts.append("  </link>")
    return "\n".join(parts)


def joint(
    name: str,
    parent: str,
    child: str,
    xyz_mm: tuple[float, ...],
    rpy: tuple[float, ...] | np.ndarray,
    limits_deg: tuple[float, float] | None,
    mimic: str | None = None,
) -> str:
    kind = "fixed" if limits_deg is None else "revolute"
    parts = [f'  <joint name="{name}" type="{kind}">', f"    {origin(xyz_mm, rpy)}"]
    parts += [f'    <parent link="{parent}"/>', f'    <child link="{child}"/>']
    if limits_deg is not None:
        lo, hi = (v * DEG for v in limits_deg)
        parts.append('    <axis xyz="0 0 1"/>')
        parts.append(f'    <limit lower="{lo:.9g}" upper="{hi:.9g}" effort="5" velocity="2"/>')
    if mimic is not None:
        parts.append(f'    <mimic joint="{mimic}" multiplier="1" offset="0"/>')
    parts.append("  </joint>")
    return "\n".join(parts)


def axis_angle_rpy(axis: tuple[float, float, float], angle_deg: float) -> np.ndarray:
    unit = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    # The 180-degree rotations meet scipy's gimbal-lock case; the angles it returns are still exact.
    warnings.filterwarnings("ignore", message="Gimbal lock")
    # URDF rpy is the fixed-axis X-Y-Z convention, which scipy calls extrinsic "xyz".
    return Rotation.from_rotvec(unit * angle_deg * DEG).as_euler("xyz")


def finger(name: str) -> list[str]:
    parent, xyz, axis, angle = ABDUCTION_FRAMES[name]
    base = "thumb_knuckle" if name == "thumb" else f"{name}_base"
    j3 = f"{name}_j3"
    return [
        link(base, "base"),
        joint(f"{name}_j1", parent, base, xyz, axis_angle_rpy(axis, angle), LIMITS_DEG["j1"]),
        link(f"{name}_proximal", "proximal"),
        # Modified DH: alpha = -90 deg about x, then the flexion joint about z.
        joint(
            f"{name}_j2",
            base,
            f"{name}_proximal",
            (0, 0, 0),
            (-math.pi / 2, 0, 0),
            LIMITS_DEG["j2"],
        ),
        link(f"{name}_middle", "middle"),
        joint(
            j3,
            f"{name}_proximal",
            f"{name}_middle",
            (PROXIMAL_LENGTH_MM, 0, 0),
            (0, 0, 0),
            LIMITS_DEG["j3"],
        ),
        link(f"{name}_distal", "distal"),
        # theta offset -90 deg turns the distal frame so that the phalanx runs along +y.
        joint(
            f"{name}_j4",
            f"{name}_middle",
            f"{name}_distal",
            (MIDDLE_LENGTH_MM, 0, 0),
            (0, 0, -math.pi / 2),
            LIMITS_DEG["j3"],
            mimic=j3,
        ),
        link(f"{name}_tip", "tip"),
        joint(
            f"{name}_tip_joint",
            f"{name}_distal",
            f"{name}_tip",
            (0, TIP_CENTRE_MM, 0),
            (0, 0, 0),
            None,
        ),
    ]


def urdf() -> str:
    parts = ['<?xml version="1.0"?>', '<robot name="sah_right">']
    # This line names the generator's original source; it stays byte-for-byte because the URDF
    # bytes are part of the hand digest that the shipped sequences are keyed by.
    parts.append("  <!-- Generated by tools/make_sah_urdf.py from shared/sah-kinematics.md. -->")
    parts.append(link("palm", "palm"))
    parts.append(link("thumb_base", "thumb_base"))
    parts.append(
        joint("thumb_j0", "palm", "thumb_base", THUMB_BASE_ORIGIN_MM, (0, 0, 0), LIMITS_DEG["j0"])
    )
    for name in FINGERS:
        parts.extend(finger(name))
    parts.append("</robot>")
    return "\n".join(parts) + "\n"


if __name__ == "__main__":
    out = Path(__file__).resolve().parent.parent / "urdf" / "sah_right.urdf"
    out.write_text(urdf(), encoding="utf-8")
    print(f"wrote {out}")
