"""A hand's kinematic tree for the compiled Levenberg-Marquardt loop (``sahgrasp/ik/_lm.c``).

The auto method's inner loop runs in one native call per start (docs/methods/ik.md, "The compiled
loop"):
in Python, the unavoidable calls of one iteration alone cost several times the compiled iteration.
The tree is read from the hand's Pinocchio model, which stays the reference: each joint's
placement, parent, configuration and velocity index, and its axis taken from Pinocchio's own
joint Jacobian (so a revolute joint of any axis, a prismatic joint and a mimic joint all read
the same way). ``tests/test_compiled.py`` checks the tree's contact stack, Jacobian and
integration against :class:`~sahgrasp.model.hand.Hand` (Pinocchio) and finite differences.
"""

from __future__ import annotations

from typing import Any, Final

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.errors import HandModelError
from sahgrasp.ik import _lm
from sahgrasp.ik._lm import Tree
from sahgrasp.model.hand import Hand

__all__ = [
    "BOX",
    "CLIMB_ABOVE",
    "CONVEX",
    "CYLINDER",
    "ELLIPSOID",
    "OUTCOMES",
    "POINT",
    "TIE_M",
    "ShapeDescription",
    "compiled_tree",
    "describe_shape",
    "near_pairs",
    "self_collides",
    "tree_joint",
]

OUTCOMES: Final = {
    _lm.CONVERGED: "converged",
    _lm.NO_PROGRESS: "no_progress",
    _lm.MAX_ITERATIONS: "max_iterations",
}
"""Outcome of :meth:`Tree.solve`, by the code it returns (the codes are ``_lm.c``'s)."""

# The shape kinds of the compiled verdicts, as ``sahgrasp/collision/_gjk.h`` numbers them (read from
# the compiled module, never copied).
POINT: Final = _lm.SHAPE_POINT
"""A point, inflated: a sphere (sizes unused)."""
BOX: Final = _lm.SHAPE_BOX
"""A box (sizes: its half extents [m])."""
CYLINDER: Final = _lm.SHAPE_CYLINDER
"""A cylinder along z (sizes: radius and half length [m]); of radius 0 and inflated, a capsule."""
ELLIPSOID: Final = _lm.SHAPE_ELLIPSOID
"""An ellipsoid (sizes: its radii [m])."""
CONVEX: Final = _lm.SHAPE_CONVEX
"""A convex hull of vertices (an object's piece; the hand's own shapes are never hulls)."""


def tree_joint(pinocchio_joint: int) -> int:
    """The compiled tree's number of Pinocchio joint ``pinocchio_joint``.

    The one mapping between the two numberings: the tree leaves out Pinocchio's universe
    (joint 0), which is the tree's fixed world ``_lm.FIXED_JOINT`` (-1), and keeps Pinocchio's
    order after it: the wrist (Pinocchio's joint 1) is the tree's root, 0. A contact's object
    is attached to the universe, so it is the tree's fixed world too.
    """
    return _lm.FIXED_JOINT + pinocchio_joint


def compiled_tree(hand: Hand) -> Tree:
    """The compiled tree of ``hand``, built on first use and kept in ``hand.cache``.

    Raises:
        HandModelError: The hand has a joint other than the free-flyer wrist and 1-DoF revolute
            or prismatic joints (the URDF checks admit no other).
    """
    return hand.cache.get("compiled_tree", lambda: _export(hand))


def self_collides(hand: Hand, q: NDArray[np.float64]) -> bool:
    """True if the hand collides with itself at ``q``, the verdict of coal's distances.

    Compiled (GJK in ``sahgrasp/collision/_gjk.h``, the shapes placed by the tree's own kinematics)
    when every collision shape is a sphere, box, cylinder, capsule or ellipsoid, as in the shipped
    hands: one native call instead of Pinocchio's and coal's broad phase through Python
    (docs/methods/ik.md, "Compiled collision verdicts"). :meth:`Hand.in_collision` answers for other
    shapes (meshes). It can differ from this verdict for pairs within GJK's tolerance of
    touching, and where Pinocchio's collision request calls clear a pair that coal's distance
    finds overlapping (docs/methods/ik.md).
    """
    tree = compiled_tree(hand)
    if not tree.shape_count:
        return hand.in_collision(q)
    return tree.pairs_within(q, 0.0, np.empty(1, dtype=np.int64)) > 0


def near_pairs(hand: Hand, q: NDArray[np.float64], margin_m: float) -> NDArray[np.intp] | None:
    """Indices of the hand's checked pairs that may be closer than ``margin_m`` >= 0 [m] at ``q``.

    Compiled: the pairs the IK's collision repair asks coal's witnesses of
    (:meth:`Hand.penetrations`), every pair closer than the margin and those within
    :data:`TIE_M` beyond it. None when the hand has shapes the compiled check does not know
    (coal then finds them).
    """
    tree = compiled_tree(hand)
    if not tree.shape_count:
        return None
    found = np.empty(tree.pair_count, dtype=np.int64)
    count = tree.pairs_within(q, margin_m + TIE_M, found)
    return found[:count].astype(np.intp)


TIE_M = 1e-9
"""Pairs (and links) this close beyond the repair's margin [m] are left to coal to decide: a
repair step puts what it separates at the margin up to rounding, where coal's test and GJK's
tolerance may differ."""


def _export(hand: Hand) -> Tree:
    tree = Tree(**_tree_arguments(hand))
    shapes = _shapes(hand.collision.geometry_model)
    if shapes is not None:
        tree.set_shapes(**shapes)
    return tree


def _tree_arguments(hand: Hand) -> dict[str, Any]:
    """The keyword arguments of :class:`Tree` for ``hand``.

    The tree's joints are Pinocchio's after its universe, numbered by :func:`tree_joint`. Per
    joint: its parent, placement in the parent (rotation row-major, then translation), unit axis
    in its own frame, whether it slides, configuration and velocity index, and the mimic scale
    and offset (1 and 0 for a joint of its own); per finger the joint that carries its contact
    frame ("yaw"); the fingertip radius [m] and the actuated joints' limits.
    """
    model = hand.model
    data = model.createData()
    pin.computeJointJacobians(model, data, pin.neutral(model))
    joints = range(1, model.njoints)
    axes, prismatic, scale, offset = [], [], [], []
    for j in joints:
        axis, slides = _joint_axis(model, data, j)
        axes.append(axis)
        prismatic.append(slides)
        joint = model.joints[j]
        mimic = joint.shortname() == "JointModelMimic"
        scale.append(float(joint.extract().scaling) if mimic else 1.0)
        offset.append(float(joint.extract().offset) if mimic else 0.0)
    placements = [
        np.concatenate([placement.rotation.ravel(), placement.translation])
        for placement in model.jointPlacements[1:]
    ]
    yaw = [tree_joint(model.frames[hand.contact_frame_id(f)].parentJoint) for f in hand.fingers]
    return {
        "parents": np.array([tree_joint(model.parents[j]) for j in joints], dtype=np.int64),
        "placements": np.ascontiguousarray(placements, dtype=np.float64),
        "axes": np.ascontiguousarray(axes, dtype=np.float64),
        "prismatic": np.array(prismatic, dtype=np.int64),
        "q_index": np.array([model.joints[j].idx_q for j in joints], dtype=np.int64),
        "v_index": np.array([model.joints[j].idx_v for j in joints], dtype=np.int64),
        "scale": np.array(scale, dtype=np.float64),
        "offset": np.array(offset, dtype=np.float64),
        "yaw": np.array(yaw, dtype=np.int64),
        "radius": hand.radius_m,
        "lower": np.ascontiguousarray(hand.lower, dtype=np.float64),
        "upper": np.ascontiguousarray(hand.upper, dtype=np.float64),
        "nq": hand.nq,
        "nv": hand.nv,
    }


CLIMB_ABOVE = 16
"""Convex shapes with more vertices than this find their support points by hill climbing on
the hull's edges (coal's vertex neighbours) instead of a scan of every vertex."""

ShapeDescription = tuple[int, list[float], NDArray[np.float64], list[list[int]] | None]
"""A shape's kind, sizes (3, then its inflation [m]), convex vertices (N, 3) and, for a hull of
more than :data:`CLIMB_ABOVE` vertices, each vertex's neighbours."""


def describe_shape(geometry: coal.CollisionGeometry) -> ShapeDescription | None:
    """A coal shape as the compiled verdicts see it; None for a kind they do not know.

    A sphere is an inflated point and a capsule an inflated segment (a cylinder of radius 0);
    coal's swept-sphere radius adds to the inflation. Sizes: box half extents, cylinder radius
    and half length, ellipsoid radii.
    """
    if not isinstance(geometry, coal.ShapeBase):  # a mesh (BVH) or an octree
        return None
    inflation = float(geometry.getSweptSphereRadius())
    no_vertices = np.empty((0, 3))
    if isinstance(geometry, coal.ConvexBase):
        points = np.asarray(geometry.points(), dtype=np.float64)
        climb = None
        if len(points) > CLIMB_ABOVE:
            climb = [list(geometry.neighbors(k)) for k in range(len(points))]
        return CONVEX, [0.0, 0.0, 0.0, inflation], points, climb
    if isinstance(geometry, coal.Box):
        return BOX, [*np.asarray(geometry.halfSide).tolist(), inflation], no_vertices, None
    if isinstance(geometry, coal.Ellipsoid):
        return ELLIPSOID, [*np.asarray(geometry.radii).tolist(), inflation], no_vertices, None
    if isinstance(geometry, coal.Sphere):
        return POINT, [0.0, 0.0, 0.0, geometry.radius + inflation], no_vertices, None
    if isinstance(geometry, coal.Cylinder):
        sizes = [geometry.radius, geometry.halfLength, 0.0, inflation]
        return CYLINDER, sizes, no_vertices, None
    if isinstance(geometry, coal.Capsule):
        sizes = [0.0, geometry.halfLength, 0.0, geometry.radius + inflation]
        return CYLINDER, sizes, no_vertices, None
    return None


def _shapes(geometry_model: pin.GeometryModel) -> dict[str, NDArray[Any]] | None:
    """The keyword arguments of :meth:`Tree.set_shapes`, None if a shape cannot be compiled.

    A hull, a shape of a kind :func:`describe_shape` does not know, or one that hangs from no
    joint of the tree leaves the hand's verdicts to coal.
    """
    joints, placements, kinds, sizes, balls = [], [], [], [], []
    for g in geometry_model.geometryObjects:
        described = describe_shape(g.geometry)
        if described is None or described[0] == CONVEX or g.parentJoint < 1:
            return None
        g.geometry.computeLocalAABB()
        joints.append(tree_joint(g.parentJoint))
        placements.append(np.concatenate([g.placement.rotation.ravel(), g.placement.translation]))
        kinds.append(described[0])
        sizes.append(described[1])
        balls.append([*np.asarray(g.geometry.aabb_center).tolist(), float(g.geometry.aabb_radius)])
    pairs = [(p.first, p.second) for p in geometry_model.collisionPairs]
    return {
        "joints": np.array(joints, dtype=np.int64),
        "placements": np.ascontiguousarray(placements, dtype=np.float64),
        "kinds": np.array(kinds, dtype=np.int64),
        "sizes": np.array(sizes, dtype=np.float64),
        "balls": np.array(balls, dtype=np.float64),
        "pairs": np.array(pairs, dtype=np.int64).reshape(-1, 2),
    }


def _joint_axis(model: pin.Model, data: pin.Data, j: int) -> tuple[list[float], bool]:
    """Unit axis of joint ``j`` in its own frame and whether it slides (prismatic).

    The root (the wrist's free flyer) has no axis. The axis is Pinocchio's motion subspace of
    the joint, its world Jacobian column (``computeJointJacobians`` done) brought into the
    joint frame.
    """
    joint = model.joints[j]
    if j == 1:
        if joint.shortname() != "JointModelFreeFlyer" or model.parents[j] != 0:
            raise HandModelError("the compiled IK needs the wrist as the root free-flyer joint")
        return [0.0, 0.0, 0.0], False
    column = data.J[:, joint.idx_vExtended]
    motion = data.oMi[j].actInv(pin.Motion(column))
    linear, angular = motion.linear, motion.angular
    for axis, other, slides in ((angular, linear, False), (linear, angular, True)):
        if abs(np.linalg.norm(axis) - 1.0) < 1e-9 and np.linalg.norm(other) < 1e-9:
            return axis.tolist(), slides
    raise HandModelError(
        f"joint {model.names[j]!r} is not a 1-DoF revolute or prismatic joint; the IK handles "
        "only those (besides the wrist)"
    )
