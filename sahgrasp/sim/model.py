"""The MuJoCo model of a grasp: the hand from its description, the object from its convex pieces.

The hand is built from the Pinocchio model :func:`~sahgrasp.model.hand.load_hand` makes of its URDF:
one body per URDF joint (fixed links merged into their parent, as Pinocchio merges them), each
URDF collision shape as a MuJoCo geom (boxes, cylinders, spheres, capsules, ellipsoids; a mesh
becomes its convex hull, as MuJoCo collides meshes), coupled (``<mimic>``) joints as joint
equality constraints, and a position servo on each independent joint with the URDF's effort limit
as its torque limit. The palm is fixed: the simulation's world frame is the palm frame, so the
wrist is welded at the grasp's pose and one compiled model serves every grasp of an object (only
the object's pose and the joint angles change). The object is a free body made of the convex
pieces the project builds for coal (:meth:`~sahgrasp.objects.GraspObject.simulation_shapes`: its
collision pieces, a mesh's merged further where its budget stopped their merge).
The hand collides with the object only (the IK already keeps the hand free of self-collision).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Any

import coal
import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.errors import HandModelError, SahGraspError
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject
from sahgrasp.sim.settings import HoldSettings

__all__ = ["SimModel", "SimModelError", "build_model"]

_VIRTUAL = ("_contact_pitch", "_contact_yaw")
_HAND_CONTYPE, _HAND_CONAFFINITY = 2, 1
_OBJECT_CONTYPE, _OBJECT_CONAFFINITY = 1, 2
"""Collision bits: a hand geom meets an object geom (2 & 2), never another hand geom (2 & 1)."""


class SimModelError(SahGraspError):
    """A hand or object cannot be turned into a MuJoCo model (unsupported joint or shape)."""


@dataclass(frozen=True, eq=False)
class SimModel:
    """A compiled MuJoCo model of one hand and one object, with the indices the test reads.

    Attributes:
        model: The MuJoCo model (world frame = palm frame).
        data: Its data (the hold test's scratch state).
        joint_names: URDF joints simulated, in MuJoCo joint order (mimic joints included).
        qpos_addresses: ``qpos`` index of each of ``joint_names``.
        dof_addresses: ``qvel`` index of each of ``joint_names``.
        actuated: Names of the servoed joints (the hand's independent joints), actuator order.
        actuated_dofs: ``qvel`` index of each actuated joint.
        mimic: Per mimic joint: (its ``qvel`` index, the leader's actuator index, multiplier).
        fingertip_geoms: Finger name -> MuJoCo geom ids of its fingertip link.
        fingertip_bodies: Finger name -> MuJoCo body id of its fingertip link.
        hand_geoms: Ids of every hand geom.
        object_body: Body id of the object.
        object_qpos: ``qpos`` index of the object's free joint (position, then quaternion w-first).
        object_dof: ``qvel`` index of the object's free joint.
        mass_kg: Object mass [kg].
        size_m: Radius of a ball about the object's centre of mass holding its pieces [m].
        geom_names: Name of each geom (for failure reasons).
    """

    model: Any
    data: Any
    joint_names: tuple[str, ...]
    qpos_addresses: NDArray[np.intp]
    dof_addresses: NDArray[np.intp]
    actuated: tuple[str, ...]
    actuated_dofs: NDArray[np.intp]
    mimic: tuple[tuple[int, int, float], ...]
    fingertip_geoms: dict[str, tuple[int, ...]]
    fingertip_bodies: dict[str, int]
    hand_geoms: NDArray[np.intp]
    object_body: int
    object_qpos: int
    object_dof: int
    mass_kg: float
    size_m: float
    geom_names: tuple[str, ...]


def _fmt(values: Any) -> str:
    return " ".join(repr(float(v)) for v in np.ravel(values))


def _pose(parent: ET.Element, tag: str, placement: pin.SE3, **attrs: str) -> ET.Element:
    quat = pin.Quaternion(placement.rotation).coeffs()  # x, y, z, w
    element = ET.SubElement(parent, tag, attrs)
    element.set("pos", _fmt(placement.translation))
    element.set("quat", _fmt([quat[3], quat[0], quat[1], quat[2]]))
    return element


def _joint_axis(hand: Hand, joint: int) -> NDArray[np.float64]:
    """Unit axis of a revolute joint in its own frame, read from its motion (mimic joints too).

    A mimic joint turns by ``multiplier * q_leader + offset``: the axis is the rotation vector of
    the motion between two leader values divided by the angle the multiplier gives.
    """
    model = hand.model
    jm = model.joints[joint]
    mimic = jm.shortname() == "JointModelMimic"
    if not mimic and (jm.nq != 1 or jm.nv != 1):
        raise SimModelError(
            f"joint {model.names[joint]!r} of hand {hand.description.name!r} is a "
            f"{jm.shortname()}; the physics model supports revolute joints only"
        )
    data = model.createData()
    scaling = float(jm.extract().scaling) if mimic else 1.0
    q0 = pin.neutral(model)
    q1 = q0.copy()
    q1[jm.idx_q] += 0.5
    motions = []
    for q in (q0, q1):
        pin.forwardKinematics(model, data, q)
        motions.append(model.jointPlacements[joint].inverse() * data.liMi[joint])
    step = motions[0].inverse() * motions[1]
    if np.linalg.norm(step.translation) > 1e-9 or scaling == 0.0:
        raise SimModelError(
            f"joint {model.names[joint]!r} of hand {hand.description.name!r} is not revolute; "
            "the physics model supports revolute joints only"
        )
    axis = pin.log3(step.rotation) / (0.5 * scaling)
    return np.asarray(axis / np.linalg.norm(axis), dtype=np.float64)


def _geom(body: ET.Element, name: str, shape: Any, placement: pin.SE3, assets: ET.Element,
          scale: NDArray[np.float64] | None = None) -> ET.Element:  # fmt: skip
    """A MuJoCo geom for a coal shape placed in ``body``; meshes become mesh assets."""
    attrs: dict[str, str]
    if isinstance(shape, coal.Box):
        attrs = {"type": "box", "size": _fmt(np.asarray(shape.halfSide))}
    elif isinstance(shape, coal.Sphere):
        attrs = {"type": "sphere", "size": _fmt([shape.radius])}
    elif isinstance(shape, coal.Cylinder):
        attrs = {"type": "cylinder", "size": _fmt([shape.radius, shape.halfLength])}
    elif isinstance(shape, coal.Capsule):
        attrs = {"type": "capsule", "size": _fmt([shape.radius, shape.halfLength])}
    elif isinstance(shape, coal.Ellipsoid):
        attrs = {"type": "ellipsoid", "size": _fmt(np.asarray(shape.radii))}
    elif isinstance(shape, (coal.ConvexBase, coal.BVHModelBase)):
        points = np.asarray(
            shape.points() if isinstance(shape, coal.ConvexBase) else shape.vertices(),
            dtype=np.float64,
        )
        if scale is not None:
            points = points * scale
        if len(points) < 4 or np.linalg.matrix_rank(points - points.mean(axis=0), 1e-9) < 3:
            raise SimModelError(f"shape {name!r} is flat or has fewer than 4 points")
        ET.SubElement(assets, "mesh", {"name": name, "vertex": _fmt(points)})
        attrs = {"type": "mesh", "mesh": name}
    else:
        raise SimModelError(
            f"shape {name!r} is a {type(shape).__name__}; the physics model supports boxes, "
            "spheres, cylinders, capsules, ellipsoids, convex pieces and meshes"
        )
    return _pose(body, "geom", placement, name=name, **attrs)


def _hand_xml(hand: Hand, world: ET.Element, assets: ET.Element, actuators: ET.Element,
              equalities: ET.Element, settings: HoldSettings) -> None:  # fmt: skip
    model = hand.model
    bodies: dict[int, ET.Element] = {}
    palm = ET.SubElement(world, "body", {"name": "palm"})  # no joint: welded to the world
    bodies[1] = palm
    mimics = hand.mimic_joints
    for j in range(2, model.njoints):
        name = str(model.names[j])
        if name.endswith(_VIRTUAL):
            continue
        parent = int(model.parents[j])
        if parent not in bodies:
            raise SimModelError(f"joint {name!r} hangs on a joint the model does not simulate")
        body = _pose(bodies[parent], "body", model.jointPlacements[j], name=name)
        bodies[j] = body
        inertia = model.inertias[j]
        mass = max(float(inertia.mass), 1e-4)
        inertia_kg_m2 = np.asarray(inertia.inertia)
        I3 = 0.5 * (inertia_kg_m2 + inertia_kg_m2.T) + np.eye(3) * 1e-9
        ET.SubElement(body, "inertial", {
            "pos": _fmt(inertia.lever), "mass": repr(mass),
            "fullinertia": _fmt([I3[0, 0], I3[1, 1], I3[2, 2], I3[0, 1], I3[0, 2], I3[1, 2]]),
        })  # fmt: skip
        jm = model.joints[j]
        joint_attrs = {
            "name": name, "type": "hinge", "axis": _fmt(_joint_axis(hand, j)),
            "armature": repr(settings.armature_kg_m2),
        }  # fmt: skip
        if name in mimics:
            leader, multiplier, offset = mimics[name]
            ET.SubElement(equalities, "joint", {
                "joint1": name, "joint2": leader, "polycoef": _fmt([offset, multiplier, 0, 0, 0]),
            })  # fmt: skip
        else:
            lo, hi = model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q]
            joint_attrs.update(limited="true", range=_fmt([lo, hi]))
            effort = float(model.effortLimit[jm.idx_v])
            if not math.isfinite(effort) or effort <= 0:
                raise SimModelError(
                    f"joint {name!r} of hand {hand.description.name!r} has no positive effort "
                    "limit in its URDF; the servos need one (<limit effort=...>)"
                )
            ET.SubElement(actuators, "position", {
                "name": name, "joint": name, "kp": repr(settings.stiffness_nm_rad),
                "kv": repr(settings.damping_nms_rad), "forcelimited": "true",
                "forcerange": _fmt([-effort, effort]),
            })  # fmt: skip
        ET.SubElement(body, "joint", joint_attrs)
    geometry = hand.collision.geometry_model
    for g in geometry.geometryObjects:
        joint = int(g.parentJoint)
        if joint not in bodies:
            raise SimModelError(f"collision shape {g.name!r} hangs on an unsimulated joint")
        element = _geom(bodies[joint], f"hand/{g.name}", g.geometry, g.placement, assets,
                        np.asarray(g.meshScale))  # fmt: skip
        element.set("contype", str(_HAND_CONTYPE))
        element.set("conaffinity", str(_HAND_CONAFFINITY))


def _object_xml(obj: GraspObject, world: ET.Element, assets: ET.Element,
                settings: HoldSettings) -> None:  # fmt: skip
    body = ET.SubElement(world, "body", {"name": "object"})
    ET.SubElement(body, "freejoint", {"name": "object"})
    for k, shape in enumerate(obj.simulation_shapes()):
        placement = pin.SE3(shape.placement[:3, :3], shape.placement[:3, 3])
        element = _geom(body, f"object/{k}", shape.geometry, placement, assets)
        element.set("contype", str(_OBJECT_CONTYPE))
        element.set("conaffinity", str(_OBJECT_CONAFFINITY))
        element.set("density", repr(settings.density_kg_m3))


def model_xml(hand: Hand, obj: GraspObject, settings: HoldSettings) -> str:
    """The MJCF text of ``hand`` with ``obj`` (world frame = palm frame)."""
    root = ET.Element("mujoco", {"model": f"{hand.description.name}-{obj.name}"})
    ET.SubElement(root, "compiler", {"angle": "radian", "autolimits": "true"})
    ET.SubElement(root, "option", {
        "timestep": repr(settings.timestep_s), "integrator": "implicitfast", "cone": "elliptic",
        "solver": "Newton", "iterations": str(settings.solver_iterations),
        "noslip_iterations": str(settings.noslip_iterations),
        "ls_iterations": str(settings.ls_iterations), "impratio": repr(settings.impratio),
        "gravity": "0 0 0",
    })  # fmt: skip
    ET.SubElement(root, "size", {"memory": "20M"})
    default = ET.SubElement(root, "default")
    # condim 3: hard-finger point contacts (Coulomb friction only); 4: soft-finger contacts,
    # torsional friction of a uniformly pressed disk of the patch radius.
    torsional_m = 2.0 / 3.0 * settings.friction * settings.patch_radius_m
    ET.SubElement(default, "geom", {
        "condim": "4" if torsional_m > 0 else "3",
        "friction": _fmt([settings.friction, torsional_m, 0.0]), "margin": "0",
        "solref": _fmt([settings.contact_timeconst_s, 1.0]),
        "solimp": _fmt([min(0.9, settings.contact_impedance), settings.contact_impedance, 0.001]),
    })  # fmt: skip
    assets = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    actuators = ET.SubElement(root, "actuator")
    equalities = ET.SubElement(root, "equality")
    _hand_xml(hand, world, assets, actuators, equalities, settings)
    _object_xml(obj, world, assets, settings)
    return ET.tostring(root, encoding="unicode")


def build_model(hand: Hand, obj: GraspObject, settings: HoldSettings | None = None) -> SimModel:
    """Compile the MuJoCo model of ``hand`` and ``obj`` (build it once per hand and object).

    The object's mass is ``settings.mass_kg``, or its pieces' volume times
    ``settings.density_kg_m3`` (pieces that overlap count twice); its inertia is the pieces'.

    Raises:
        SimModelError: An unsupported joint or shape, or MuJoCo refuses the model.
    """
    settings = settings or HoldSettings()
    xml = model_xml(hand, obj, settings)
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as exc:
        raise SimModelError(f"MuJoCo cannot build the model of {obj.name!r}: {exc}") from exc
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "object")
    if settings.mass_kg is not None:
        scale = settings.mass_kg / float(model.body_mass[body])
        model.body_mass[body] *= scale
        model.body_inertia[body] *= scale
    data = mujoco.MjData(model)
    mujoco.mj_setConst(model, data)
    names, qpos, dofs = [], [], []
    for j in range(model.njnt):
        if model.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            names.append(mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_JOINT, j))
            qpos.append(model.jnt_qposadr[j])
            dofs.append(model.jnt_dofadr[j])
    actuated = tuple(
        mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(model.nu)
    )
    dof_of = dict(zip(names, dofs, strict=True))
    mimic = tuple(
        (int(dof_of[m]), actuated.index(leader), float(mult))
        for m, (leader, mult, _) in hand.mimic_joints.items()
    )
    tips: dict[str, tuple[int, ...]] = {}
    tip_bodies: dict[str, int] = {}
    geometry = hand.collision.geometry_model
    for spec in hand.description.fingers:
        frame = hand.model.getFrameId(spec.tip_link)
        joint = int(hand.model.frames[frame].parentJoint)
        own = [g.name for g in geometry.geometryObjects if int(g.parentFrame) == frame]
        if not own:  # the tip link has no shape of its own: every shape of its body
            own = [g.name for g in geometry.geometryObjects if int(g.parentJoint) == joint]
        if not own:
            raise HandModelError(f"fingertip link {spec.tip_link!r} has no collision shape")
        ids = tuple(mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"hand/{n}") for n in own)
        tips[spec.name] = ids
        tip_bodies[spec.name] = int(model.geom_bodyid[ids[0]])
    hand_geoms = np.array(
        [g for g in range(model.ngeom) if model.geom_bodyid[g] != body], dtype=np.intp
    )
    object_geoms = np.flatnonzero(model.geom_bodyid == body)
    mujoco.mj_kinematics(model, data)  # no collision pass: the object sits in the palm here
    com = data.xipos[body].copy()
    size = float(
        np.max(
            np.linalg.norm(data.geom_xpos[object_geoms] - com, axis=1)
            + model.geom_rbound[object_geoms]
        )
    )
    joint = model.body_jntadr[body]
    return SimModel(
        model=model,
        data=data,
        joint_names=tuple(names),
        qpos_addresses=np.array(qpos, dtype=np.intp),
        dof_addresses=np.array(dofs, dtype=np.intp),
        actuated=actuated,
        actuated_dofs=np.array([dof_of[a] for a in actuated], dtype=np.intp),
        mimic=mimic,
        fingertip_geoms=tips,
        fingertip_bodies=tip_bodies,
        hand_geoms=hand_geoms,
        object_body=int(body),
        object_qpos=int(model.jnt_qposadr[joint]),
        object_dof=int(model.jnt_dofadr[joint]),
        mass_kg=float(model.body_mass[body]),
        size_m=size,
        geom_names=tuple(
            mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(model.ngeom)
        ),
    )
