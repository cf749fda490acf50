"""The feasible-grasp system F(x) = 0 of atlas-grasp-optimization (Section II) on a sahgrasp hand.

Frame: the palm (the paper's absolute frame is attached to the palm, so the wrist does not enter x).
Variables ``x = [x_h, x_c, x_o]``:

* ``x_h`` -- the coordinates of every finger that touches the object: its joints (mimic joints
  follow their leader, so Eq. (1) holds by construction) and its two virtual contact joints, which
  place the touching point on the fingertip sphere (passive: the fingertip rolls);
* ``x_c`` -- the parameters of each finger's contact region (Eqs. (3)-(4)): ``(u, v)`` on a patch,
  ``u`` on a curve, none at a fixed point of the object;
* ``x_o`` -- the object pose when it is free: a translation and a rotation vector, world-aligned,
  about the pose of the first grasp (Eq. (2) holds by construction); or none, object fixed in the
  palm.

Contacts, Eqs. (7)-(8): the fingertip point equals the object point (3 equations), and the object
normal is anti-parallel to the fingertip normal, written as two equations ``m_i . b_1 = 0``,
``m_i . b_2 = 0`` with ``b_1, b_2`` the tangent axes of the fingertip's contact frame (smooth, full
rank, first derivatives only; the sign is kept by continuity from the first grasp).

Dimension reduction (Section III): the PCA of sampled hand configurations gives ``E``; the ``s``
directions of least variance, through the first grasp ``x_1``, add ``E_s^T (x_h - x_1h) = 0``
(Eq. (13)), with ``s = t - k`` (Eq. (12)).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.errors import AtlasError
from sahgrasp.hand import Hand
from sahgrasp.objects.patches import ContactRegion, GraspPatches

__all__ = ["GraspSystem", "PrincipalMotions", "principal_motions", "reduced_system"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _skew(v: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass(frozen=True)
class _Contact:
    finger: str
    region: ContactRegion  # in the object frame
    params: slice  # its parameters in x
    frame: int  # the fingertip's contact frame


class GraspSystem:
    """F(x) = 0 for a hand, an object's contact regions, and a first feasible grasp.

    Args:
        hand: The hand.
        patches: Contact regions per finger, in the object frame.
        q_first: A hand configuration solving the grasp at the regions' nominal parameters (from
            the IK), with the object frame as world.
        free_object: Let the object pose vary (6 variables); else it is fixed in the palm.
    """

    def __init__(
        self, hand: Hand, patches: GraspPatches, q_first: NDArray[np.float64], free_object: bool
    ) -> None:
        self.hand = hand
        self.patches = patches
        self.free_object = free_object
        fingers = [f for f in hand.fingers if f in patches.regions]
        self.coordinates = np.array(
            sorted({int(i) for f in fingers for i in hand.finger_coordinates[f]}), dtype=np.intp
        )
        virtual = set(hand.virtual_joint_names)
        self.actuated_rows = np.array(
            [r for r, i in enumerate(self.coordinates) if hand.coordinate_names[i] not in virtual],
            dtype=np.intp,
        )
        contacts, offset = [], len(self.coordinates)
        for f in fingers:
            region = patches.regions[f]
            dim = len(region.lower)
            contacts.append(
                _Contact(f, region, slice(offset, offset + dim), hand.contact_frame_id(f))
            )
            offset += dim
        self.contacts = tuple(contacts)
        self.pose_slice = slice(offset, offset + (6 if free_object else 0))
        self.n = self.pose_slice.stop
        self.m = 5 * len(contacts)
        self.q_first = np.array(q_first, dtype=np.float64)
        self.T_palm_object0 = hand.wrist_pose(q_first).inverse()
        self.x_first = self._first_point()

    # ----- layout ---------------------------------------------------------------------------
    @property
    def t(self) -> int:
        """Dimension of the feasible-grasp manifold F: ``n - m``."""
        return self.n - self.m

    @property
    def hand_rows(self) -> NDArray[np.intp]:
        """Indices of ``x_h`` in ``x``."""
        return np.arange(len(self.coordinates))

    @property
    def lower(self) -> NDArray[np.float64]:
        """Box bounds: joint limits and contact regions, parameter ranges; object pose free."""
        return self._bounds(self.hand.lower, "lower", -np.inf)

    @property
    def upper(self) -> NDArray[np.float64]:
        """Upper box bounds (see :attr:`lower`)."""
        return self._bounds(self.hand.upper, "upper", np.inf)

    def _bounds(self, limits: NDArray[np.float64], side: str, pose: float) -> NDArray[np.float64]:
        out = np.full(self.n, pose)
        out[self.hand_rows] = limits[self.coordinates]
        for c in self.contacts:
            out[c.params] = getattr(c.region, side)
        return out

    def _first_point(self) -> NDArray[np.float64]:
        x = np.zeros(self.n)
        x[self.hand_rows] = self.q_first[7:][self.coordinates]
        for c in self.contacts:
            x[c.params] = c.region.nominal
        return x

    def configuration(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Hand configuration at ``x`` with the palm at the origin (other fingers as at first)."""
        q = self.q_first.copy()
        q[:7] = pin.SE3ToXYZQUAT(pin.SE3.Identity())
        q[7:][self.coordinates] = x[self.hand_rows]
        return q

    def object_pose(self, x: NDArray[np.float64]) -> pin.SE3:
        """Object pose in the palm frame at ``x``."""
        T0 = self.T_palm_object0
        if not self.free_object:
            return T0
        xo = x[self.pose_slice]
        return pin.SE3(pin.exp3(xo[3:]) @ T0.rotation, T0.translation + xo[:3])

    # ----- F and its Jacobian ----------------------------------------------------------------
    def _kinematics(self, x: NDArray[np.float64], jacobians: bool) -> list[Any]:
        model, data = self.hand.model, self.hand.data
        q = self.configuration(x)
        if jacobians:
            pin.computeJointJacobians(model, data, q)
        else:
            pin.forwardKinematics(model, data, q)
        return [pin.updateFramePlacement(model, data, c.frame) for c in self.contacts]

    def F(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Residual of Eqs. (7)-(8) per contact: point (3) [m], normal alignment (2) [1]."""
        frames = self._kinematics(x, jacobians=False)
        T = self.object_pose(x)
        out = np.empty(self.m)
        for i, (c, frame) in enumerate(zip(self.contacts, frames, strict=True)):
            jet = c.region.evaluate(x[c.params])
            R = frame.rotation
            out[5 * i : 5 * i + 3] = frame.translation - T.act(jet.point)
            out[5 * i + 3 : 5 * i + 5] = R[:, 1:].T @ (T.rotation @ jet.normal)
        return out

    def J(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian of :meth:`F` w.r.t. ``x``, shape (m, n)."""
        frames = self._kinematics(x, jacobians=True)
        model, data = self.hand.model, self.hand.data
        cols = 6 + self.coordinates  # v columns of x_h
        T = self.object_pose(x)
        out = np.zeros((self.m, self.n))
        for i, (c, frame) in enumerate(zip(self.contacts, frames, strict=True)):
            point_rows, normal_rows = slice(5 * i, 5 * i + 3), slice(5 * i + 3, 5 * i + 5)
            J = pin.getFrameJacobian(model, data, c.frame, _LWA)[:, cols]
            jet = c.region.evaluate(x[c.params])
            normal = T.rotation @ jet.normal
            axes = frame.rotation[:, 1:]  # b_1, b_2
            out[point_rows, self.hand_rows] = J[:3]
            # d(b_j) = omega x b_j, so d(m . b_j) = m . (omega x b_j) = (b_j x m) . omega
            out[normal_rows, self.hand_rows] = np.cross(axes.T, normal) @ J[3:]
            out[point_rows, c.params] = -T.rotation @ jet.point_jacobian
            out[normal_rows, c.params] = axes.T @ (T.rotation @ jet.normal_jacobian)
            if self.free_object:
                xo = x[self.pose_slice]
                Jl = pin.Jexp3(xo[3:]).T  # d(exp3(w) R0 a)/dw = -[exp3(w) R0 a]x Jl(w)
                lever = T.act(jet.point) - T.translation
                position, rotation = self.pose_slice.start, self.pose_slice.start + 3
                out[point_rows, position:rotation] = -np.eye(3)
                out[point_rows, rotation : self.pose_slice.stop] = _skew(lever) @ Jl
                out[normal_rows, rotation : self.pose_slice.stop] = -axes.T @ _skew(normal) @ Jl
        return out

    def hard_finger_constraints(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Velocity constraints ``J_h qdot - G^T nu = 0`` of hard-finger contacts at ``x``.

        Bicchi & Prattichizzo's manipulability (the paper's [1]) assumes contacts that do not
        slip: the velocity of the fingertip's material point at each contact equals the velocity
        of the object's point there. Unknowns: the actuated joint velocities ``qdot`` (the rows
        :attr:`actuated_rows` of ``x_h``) then the object twist ``nu`` (world-aligned at its
        origin). Shape (3 contacts, a + 6).
        """
        frames = self._kinematics(x, jacobians=True)
        model, data = self.hand.model, self.hand.data
        cols = 6 + self.coordinates[self.actuated_rows]
        origin = self.object_pose(x).translation
        out = np.zeros((3 * len(self.contacts), len(cols) + 6))
        for i, (c, frame) in enumerate(zip(self.contacts, frames, strict=True)):
            tip = model.getFrameId(
                self.hand.description.fingers[self.hand.fingers.index(c.finger)].tip_link
            )
            J = pin.getFrameJacobian(model, data, tip, _LWA)[:, cols]
            centre = pin.updateFramePlacement(model, data, tip).translation
            rows = slice(3 * i, 3 * i + 3)
            out[rows, : len(cols)] = J[:3] - _skew(frame.translation - centre) @ J[3:]
            out[rows, len(cols) : len(cols) + 3] = -np.eye(3)
            out[rows, len(cols) + 3 :] = _skew(frame.translation - origin)
        return out

    def object_velocity(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Matrix (6, n) giving the object's twist (world-aligned at its origin) from ``dx``."""
        out = np.zeros((6, self.n))
        if self.free_object:
            xo = x[self.pose_slice]
            out[:3, self.pose_slice.start : self.pose_slice.start + 3] = np.eye(3)
            out[3:, self.pose_slice.start + 3 : self.pose_slice.stop] = pin.Jexp3(xo[3:]).T
        return out


@dataclass(frozen=True)
class PrincipalMotions:
    """PCA of hand configurations (Section III): directions ``E`` (columns) and variances ``S^2``.

    Attributes:
        mean: Average configuration, shape (h,).
        directions: ``E``, orthonormal columns sorted by decreasing variance, shape (h, h).
        variances: ``S^2`` in the same order, shape (h,).
    """

    mean: NDArray[np.float64]
    directions: NDArray[np.float64]
    variances: NDArray[np.float64]

    def constraints(self, s: int) -> NDArray[np.float64]:
        """``E_s^T``: the ``s`` directions of least variance, as rows (Eq. (10))."""
        h = len(self.variances)
        if not 0 <= s < h:
            raise AtlasError(f"s = t - k must satisfy 0 <= s < h = {h}, got s = {s}")
        return self.directions[:, h - s :].T

    def retained_variance(self, s: int) -> float:
        """Share of the variance kept by the first ``h - s`` motions."""
        return float(self.variances[: len(self.variances) - s].sum() / self.variances.sum())


def principal_motions(samples: NDArray[np.float64]) -> PrincipalMotions:
    """PCA of a set of hand configurations (rows): ``T T^T = E S^2 E^T`` (Section III)."""
    mean = samples.mean(axis=0)
    centred = samples - mean
    variances, E = np.linalg.eigh(centred.T @ centred / max(len(samples) - 1, 1))
    order = np.argsort(variances)[::-1]
    return PrincipalMotions(mean, E[:, order], variances[order])


def reduced_system(
    system: GraspSystem, motions: PrincipalMotions, k: int, x1: NDArray[np.float64] | None = None
) -> tuple[Any, Any]:
    """``R(x) = 0`` (Eq. (11)): F plus ``E_s^T (x_h - x_1h) = 0`` (Eq. (13)), ``s = t - k``.

    ``x1`` is the first feasible grasp the principal motions pass through (default: the IK's).
    """
    if not 1 <= k <= system.t:
        raise AtlasError(f"k must be between 1 and t = {system.t}, got {k}")
    Es = motions.constraints(system.t - k)
    rows = system.hand_rows
    x1h = (system.x_first if x1 is None else x1)[rows]

    def R(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([system.F(x), Es @ (x[rows] - x1h)])

    def JR(x: NDArray[np.float64]) -> NDArray[np.float64]:
        linear = np.zeros((len(Es), system.n))
        linear[:, rows] = Es
        return np.vstack([system.J(x), linear])

    return R, JR
