"""A hand's kinematic tree for the compiled Levenberg-Marquardt loop (``sahgrasp/ik/_lm.c``).

The auto method's inner loop runs in one native call per start (docs/ik.md, "Compiled loop"):
Python measured at least 37 us of unavoidable calls per iteration against the issue's 30 us.
The tree is read from the hand's Pinocchio model, which stays the reference: each joint's
placement, parent, configuration and velocity index, and its axis taken from Pinocchio's own
joint Jacobian (so a revolute joint of any axis, a prismatic joint and a mimic joint all read
the same way). ``tests/test_compiled.py`` checks the tree's contact stack, Jacobian and
integration against :class:`~sahgrasp.hand.Hand` (Pinocchio) and finite differences.
"""

from __future__ import annotations

import weakref
from typing import Final

import numpy as np
import pinocchio as pin

from sahgrasp.errors import HandModelError
from sahgrasp.hand import Hand
from sahgrasp.ik._lm import CONVERGED, MAX_ITERATIONS, NO_PROGRESS, Tree

__all__ = ["OUTCOMES", "compiled_tree"]

OUTCOMES: Final = {
    CONVERGED: "converged",
    NO_PROGRESS: "no_progress",
    MAX_ITERATIONS: "max_iterations",
}
"""Outcome of :meth:`Tree.solve`, by the code it returns."""

_TREES: weakref.WeakKeyDictionary[Hand, Tree] = weakref.WeakKeyDictionary()


def compiled_tree(hand: Hand) -> Tree:
    """The compiled tree of ``hand``, built on first use and kept while the hand lives.

    Raises:
        HandModelError: The hand has a joint other than the free-flyer wrist and 1-DoF revolute
            or prismatic joints (the URDF checks admit no other).
    """
    tree = _TREES.get(hand)
    if tree is None:
        tree = _TREES[hand] = _export(hand)
    return tree


def _export(hand: Hand) -> Tree:
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
    yaw = [model.frames[hand.contact_frame_id(f)].parentJoint - 1 for f in hand.fingers]
    return Tree(
        parents=np.array([model.parents[j] - 1 for j in joints], dtype=np.int64),
        placements=np.ascontiguousarray(placements, dtype=np.float64),
        axes=np.ascontiguousarray(axes, dtype=np.float64),
        prismatic=np.array(prismatic, dtype=np.int64),
        q_index=np.array([model.joints[j].idx_q for j in joints], dtype=np.int64),
        v_index=np.array([model.joints[j].idx_v for j in joints], dtype=np.int64),
        scale=np.array(scale),
        offset=np.array(offset),
        yaw=np.array(yaw, dtype=np.int64),
        radius=hand.radius_m,
        lower=np.ascontiguousarray(hand.lower),
        upper=np.ascontiguousarray(hand.upper),
        nq=hand.nq,
        nv=hand.nv,
    )


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
