"""The feasible-grasp system F(x) = 0 of the atlas paper (Section II) on a sahgrasp hand.

Frame: the palm (the paper's absolute frame is attached to the palm, so the wrist does not enter x).
Variables ``x = [x_h, x_c, x_o]``:

* ``x_h`` -- the coordinates of every finger that touches the object: its joints (mimic joints
  follow their leader, so Eq. (1) holds by construction) and its two virtual contact joints, which
  place the touching point on the fingertip sphere (passive: the fingertip rolls);
* ``x_c`` -- the parameters of each finger's contact region (Eqs. (3)-(4)): ``(u, v)`` on a patch,
  ``u`` on a curve, none at a fixed point of the object;
* ``x_o`` -- the object pose when it is free: a translation and a rotation vector, world-aligned,
  about the pose of the first grasp (Eq. (2) holds by construction); or none, object fixed in the
  palm. When every contact region is a surface of revolution about one object axis, spinning the
  object about it while every contact slides back by the same angle leaves the grasp unchanged:
  a direction of F along which nothing physical moves. Given that ``symmetry_axis``, the rotation
  vector is kept normal to it at the first grasp (two coordinates): every object orientation is
  still reached once, as a swing of the first one (times a spin, which the contacts absorb).

Contacts, Eqs. (7)-(8): the fingertip point equals the object point (3 equations), and the object
normal is anti-parallel to the fingertip normal, written as two equations ``m_i . b_1 = 0``,
``m_i . b_2 = 0`` with ``b_1, b_2`` the tangent axes of the fingertip's contact frame (smooth, full
rank, first derivatives only; the sign is kept by continuity from the first grasp).

Dimension reduction (Section III): the PCA of sampled hand configurations gives ``E``; the ``s``
directions of least variance, through the first grasp ``x_1``, add ``E_s^T (x_h - x_1h) = 0``
(Eq. (13)), with ``s = t - k`` (Eq. (12)). :class:`HandGraspManifold` is that reduced set R as a
:class:`~sahgrasp.optimization.optimizer.GraspManifold`, with the collision checks of its chart
centres: at each, the fingers without a contact region are first placed where they touch nothing
(``HandObjectClearance.place_free_fingers``: the nearest configuration of their own joints clear of
the object and of the other links; they are no part of F, so this changes neither the grasp nor its
index), then the hand is checked for self-collision and, given the object, for hand-object
collision (any link inside the object, the contact fingertip spheres excepted up to ``d_min``).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from concurrent.futures import Executor
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from sahgrasp.collision.hand_object import HandObjectClearance
from sahgrasp.core.errors import GraspSystemError, OptimizationError
from sahgrasp.ik import IKSettings, solve_ik
from sahgrasp.ik.batch import object_key, worker_hand, worker_obstacle
from sahgrasp.ik.obstacle import checker_of
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, HandDescription
from sahgrasp.objects import GraspObject
from sahgrasp.objects.patches import ContactRegion, GraspPatches
from sahgrasp.objects.smooth_surface import fit_mesh_patch
from sahgrasp.optimization.motions import PrincipalMotions, principal_motions
from sahgrasp.optimization.optimizer import ChartChecks
from sahgrasp.quality.ellipsoids import Manipulability, ellipsoid_indices, null_space

__all__ = [
    "MOTION_SOURCES",
    "GraspSystem",
    "HandGraspManifold",
    "coordinate_scales",
    "first_grasp_system",
    "free_fingers",
    "hand_motions",
    "ik_seeds",
    "make_mesh_manifold",
    "make_sah_manifold",
    "mesh_patches",
    "reduced_system",
]

FloatArray = NDArray[np.float64]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def __getattr__(name: str) -> Any:
    # SahGraspManifold, the old name of HandGraspManifold (it takes any hand), for one release.
    if name == "SahGraspManifold":
        warnings.warn(
            "sahgrasp.optimization.grasp.SahGraspManifold is deprecated; use HandGraspManifold",
            DeprecationWarning,
            stacklevel=2,
        )
        return HandGraspManifold
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _skew(v: FloatArray) -> FloatArray:
    """Cross-product matrices ``[v]x`` of vectors (..., 3), shape (..., 3, 3)."""
    S = np.zeros((*v.shape[:-1], 3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S


@dataclass(frozen=True)
class _Contact:
    finger: str
    region: ContactRegion  # in the object frame
    params: slice  # its parameters in x
    frame: int  # the fingertip's contact frame


@dataclass(eq=False)
class _Point:
    """Kinematics, region jets and F at one ``x`` (palm frame, stacked over the c contacts)."""

    key: bytes  # the bytes of x
    rotation_vector: FloatArray  # of the object, from its first orientation, (3,)
    rotation: FloatArray  # object orientation, (3, 3)
    origin: FloatArray  # object origin, (3,)
    axes: FloatArray  # tangent axes b_1, b_2 of the fingertip contact frames, (c, 3, 2)
    frame_jacobians: FloatArray  # of the contact frames, columns of x_h, (c, 6, h)
    points: FloatArray  # object contact points o_i, (c, 3)
    normals: FloatArray  # object normals m_i, (c, 3)
    point_jacobians: FloatArray  # dO/d(region params) in the object frame, (3, p)
    normal_jacobians: FloatArray  # dM/d(region params) in the object frame, (3, p)
    residual: FloatArray  # F, read-only
    jacobian: FloatArray | None = None  # J once asked for, read-only


class GraspSystem:
    """F(x) = 0 for a hand, an object's contact regions, and a first feasible grasp.

    F and J share one evaluation of the kinematics and of the region jets per point: the last
    point's are kept, so ``J(x)`` after ``F(x)`` (a Newton step, a tangent space) only assembles
    the Jacobian. Both return read-only arrays.

    Args:
        hand: The hand.
        patches: Contact regions per finger, in the object frame.
        q_first: A hand configuration solving the grasp at the regions' nominal parameters (from
            the IK), with the object frame as world.
        free_object: Let the object pose vary (6 variables); else it is fixed in the palm.
        symmetry_axis: An axis (object frame) of rotational symmetry of every contact region: the
            free object's spin about it is left out of ``x_o`` (5 variables).
    """

    def __init__(
        self,
        hand: Hand,
        patches: GraspPatches,
        q_first: NDArray[np.float64],
        free_object: bool,
        symmetry_axis: ArrayLike | None = None,
    ) -> None:
        self.hand = hand
        # Its own Pinocchio Data: F and J read the kinematics they computed, whatever else
        # queries the hand in between.
        self._data = hand.model.createData()
        self.patches = patches
        self.free_object = free_object
        fingers = [f for f in hand.fingers if f in patches.regions]
        self.coordinates = np.array(
            sorted({int(i) for f in fingers for i in hand.finger_coordinates[f]}), dtype=np.intp
        )
        self.hand_rows = np.arange(len(self.coordinates))  # of x_h in x: its first entries
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
        self.q_first = np.array(q_first, dtype=np.float64)
        self.T_palm_object0 = hand.wrist_pose(q_first).inverse()
        self._rotation0 = self.T_palm_object0.rotation  # copies, kept for F's hot path
        self._origin0 = self.T_palm_object0.translation
        self._rotation_basis = self._rotations(symmetry_axis)  # rotation vector = basis @ x_o[3:]
        pose = 3 + self._rotation_basis.shape[1] if free_object else 0
        self.pose_slice = slice(offset, offset + pose)
        self.n = self.pose_slice.stop
        self.m = 5 * len(contacts)
        self._q_palm = self.q_first.copy()  # the first grasp with the palm at the origin
        hand.wrist_part(self._q_palm)[:] = pin.SE3ToXYZQUAT(pin.SE3.Identity())
        self._columns = 6 + self.coordinates  # v columns of x_h
        sizes = [c.params.stop - c.params.start for c in self.contacts]
        self._param_contact = np.repeat(np.arange(len(self.contacts)), sizes)  # owner of each
        self._param_columns = np.arange(len(self.coordinates), self.pose_slice.start)
        self._last: _Point | None = None
        self.x_first = self._first_point()

    def _rotations(self, symmetry_axis: ArrayLike | None) -> FloatArray:
        """Basis (3, 3 or 2) of the object's rotation vectors: all, or those normal to the axis."""
        if symmetry_axis is None:
            return np.eye(3)
        axis = np.asarray(symmetry_axis, dtype=np.float64)
        if axis.shape != (3,) or not np.linalg.norm(axis) > 0:
            raise GraspSystemError(
                f"symmetry_axis must be a non-zero 3-vector, got {symmetry_axis!r}"
            )
        axis = self.T_palm_object0.rotation @ axis
        return np.linalg.svd(axis[None, :])[2][1:].T  # the plane normal to the axis

    # ----- layout ---------------------------------------------------------------------------
    @property
    def t(self) -> int:
        """Dimension of the feasible-grasp manifold F: ``n - m``."""
        return self.n - self.m

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
        x[self.hand_rows] = self.hand.finger_part(self.q_first)[self.coordinates]
        for c in self.contacts:
            x[c.params] = c.region.nominal
        return x

    def point(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The ``x`` of a grasp ``q`` of the regions at their nominal parameters.

        ``q`` has the object frame as world, as the IK solves it. The object's rotation from its
        first orientation is expressed in the rotation basis (with a symmetry axis, its spin about
        the axis is dropped: Newton's method onto F lets the contacts absorb it).
        """
        x = self.x_first.copy()
        x[self.hand_rows] = self.hand.finger_part(np.asarray(q, dtype=np.float64))[self.coordinates]
        if self.free_object:
            T = self.hand.wrist_pose(q).inverse()  # the object in the palm frame
            T0 = self.T_palm_object0
            start = self.pose_slice.start
            x[start : start + 3] = T.translation - T0.translation
            turn = pin.log3(T.rotation @ T0.rotation.T)
            x[start + 3 : self.n] = np.linalg.lstsq(self._rotation_basis, turn, rcond=None)[0]
        return x

    def configuration(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Hand configuration at ``x`` with the palm at the origin (other fingers as at first)."""
        q = self._q_palm.copy()
        self.hand.finger_part(q)[self.coordinates] = x[self.hand_rows]
        return q

    def _rotation_vector(self, x: NDArray[np.float64]) -> FloatArray:
        """The object's rotation (world-aligned) from its first orientation; zero when fixed."""
        if not self.free_object:
            return np.zeros(3)
        return self._rotation_basis @ x[self.pose_slice.start + 3 : self.n]

    def object_pose(self, x: NDArray[np.float64]) -> pin.SE3:
        """Object pose in the palm frame at ``x``."""
        if not self.free_object:
            return self.T_palm_object0
        return pin.SE3(*self._pose(x, self._rotation_vector(x)))

    def _pose(
        self, x: NDArray[np.float64], rotation_vector: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """Object rotation (3, 3) and origin (3,) in the palm frame at ``x``, as numpy arrays.

        F's hot path: no ``pin.SE3`` is built and the rotation vector is computed once.
        """
        if not self.free_object:
            return self._rotation0, self._origin0
        shift = x[self.pose_slice.start : self.pose_slice.start + 3]
        return pin.exp3(rotation_vector) @ self._rotation0, self._origin0 + shift

    # ----- F and its Jacobian ----------------------------------------------------------------
    def _frames(self, x: NDArray[np.float64]) -> tuple[FloatArray, FloatArray]:
        """Contact frame placements (c, 4, 4) and Jacobians (c, 6, h) (palm-aligned) at ``x``."""
        model, data = self.hand.model, self._data
        pin.computeJointJacobians(model, data, self.configuration(x))
        placements = [pin.updateFramePlacement(model, data, c.frame) for c in self.contacts]
        jacobians = [pin.getFrameJacobian(model, data, c.frame, _LWA) for c in self.contacts]
        columns = np.array(jacobians)[:, :, self._columns]
        return np.array([M.homogeneous for M in placements]), columns

    def _point(self, x: NDArray[np.float64]) -> _Point:
        """Everything F and J need at ``x``; the last point's when ``x`` is the same."""
        x = np.asarray(x, dtype=np.float64)
        key = x.tobytes()
        if self._last is not None and self._last.key == key:
            return self._last
        placements, frame_jacobians = self._frames(x)
        jets = [c.region.evaluate(x[c.params]) for c in self.contacts]
        rotation_vector = self._rotation_vector(x)
        rotation, origin = self._pose(x, rotation_vector)
        points = np.array([j.point for j in jets]) @ rotation.T + origin
        normals = np.array([j.normal for j in jets]) @ rotation.T
        axes = placements[:, :3, 1:3]
        per_contact = np.empty((len(self.contacts), 5))
        per_contact[:, :3] = placements[:, :3, 3] - points  # p_i = o_i, Eq. (7)
        per_contact[:, 3:] = np.einsum("cij,ci->cj", axes, normals)  # m_i . b_j = 0, Eq. (8)
        residual = per_contact.reshape(self.m)
        residual.flags.writeable = False
        self._last = _Point(
            key=key,
            rotation_vector=rotation_vector,
            rotation=rotation,
            origin=origin,
            axes=axes,
            frame_jacobians=frame_jacobians,
            points=points,
            normals=normals,
            point_jacobians=np.concatenate([j.point_jacobian for j in jets], axis=1),
            normal_jacobians=np.concatenate([j.normal_jacobian for j in jets], axis=1),
            residual=residual,
        )
        return self._last

    def F(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Residual of Eqs. (7)-(8) per contact: point (3) [m], normal alignment (2) [1]."""
        return self._point(x).residual

    def J(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian of :meth:`F` w.r.t. ``x``, shape (m, n)."""
        point = self._point(x)
        if point.jacobian is None:
            point.jacobian = self._jacobian(point)
        return point.jacobian

    def _jacobian(self, p: _Point) -> FloatArray:
        """J from the kinematics and jets kept at ``p``, stacked over the contacts."""
        c, h = len(self.contacts), len(self.coordinates)
        out = np.zeros((c, 5, self.n))
        skews = _skew(np.concatenate((p.normals, p.points - p.origin)))
        # d(b_j) = omega x b_j, so d(m . b_j) = m . (omega x b_j) = b_j^T [m]x omega
        turn = np.swapaxes(p.axes, 1, 2) @ skews[:c]  # (c, 2, 3)
        out[:, :3, :h] = p.frame_jacobians[:, :3]
        out[:, 3:, :h] = turn @ p.frame_jacobians[:, 3:]
        owner, columns = self._param_contact, self._param_columns
        out[owner, :3, columns] = -(p.rotation @ p.point_jacobians).T
        normal_rates = p.rotation @ p.normal_jacobians  # (3, p)
        out[owner, 3:, columns] = np.einsum("qij,iq->qj", p.axes[owner], normal_rates)
        if self.free_object:
            start = self.pose_slice.start
            # d(exp3(w) R0 a)/dw = -[exp3(w) R0 a]x Jl(w), w = basis @ x_o[3:]
            rates = pin.Jexp3(p.rotation_vector).T @ self._rotation_basis
            out[:, :3, start : start + 3] = -np.eye(3)
            out[:, :3, start + 3 : self.n] = skews[c:] @ rates
            out[:, 3:, start + 3 : self.n] = -turn @ rates
        jacobian = out.reshape(self.m, self.n)
        jacobian.flags.writeable = False
        return jacobian

    def hard_finger_constraints(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Velocity constraints ``J_h qdot - G^T nu = 0`` of hard-finger contacts at ``x``.

        Bicchi & Prattichizzo's manipulability (the paper's [1]) assumes contacts that do not
        slip: the velocity of the fingertip's material point at each contact equals the velocity
        of the object's point there. With the virtual contact joints held, the contact frame is
        that material point, so ``J_h`` is its Jacobian at the actuated columns. Unknowns: the
        actuated joint velocities ``qdot`` (the rows :attr:`actuated_rows` of ``x_h``) then the
        object twist ``nu`` (world-aligned at its origin). Shape (3 contacts, a + 6).
        """
        placements, jacobians = self._frames(x)
        a = len(self.actuated_rows)
        out = np.zeros((len(self.contacts), 3, a + 6))
        out[:, :, :a] = jacobians[:, :3, self.actuated_rows]
        out[:, :, a : a + 3] = -np.eye(3)  # object point velocity: v + w x (p - origin)
        out[:, :, a + 3 :] = _skew(placements[:, :3, 3] - self.object_pose(x).translation)
        return out.reshape(3 * len(self.contacts), a + 6)

    def object_velocity(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """Matrix (6, n) giving the object's twist (world-aligned at its origin) from ``dx``."""
        out = np.zeros((6, self.n))
        if self.free_object:
            start = self.pose_slice.start
            out[:3, start : start + 3] = np.eye(3)
            rates = pin.Jexp3(self._rotation_vector(x)).T
            out[3:, start + 3 : self.n] = rates @ self._rotation_basis
        return out


def reduced_system(
    system: GraspSystem, motions: PrincipalMotions, k: int, x1: NDArray[np.float64] | None = None
) -> tuple[Any, Any]:
    """``R(x) = 0`` (Eq. (11)): F plus ``E_s^T (x_h - x_1h) = 0`` (Eq. (13)), ``s = t - k``.

    ``x1`` is the first feasible grasp the principal motions pass through (default: the IK's).
    """
    if not 1 <= k <= system.t:
        raise GraspSystemError(f"k must be between 1 and t = {system.t}, got {k}")
    Es = motions.constraints(system.t - k)
    rows = system.hand_rows
    x1h = (system.x_first if x1 is None else x1)[rows]
    linear = np.zeros((len(Es), system.n))
    linear[:, rows] = Es

    def R(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([system.F(x), Es @ (x[rows] - x1h)])

    def JR(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.concatenate([system.J(x), linear])

    return R, JR


# ----- a hand's grasp system as a grasp manifold -------------------------------------------------
class HandGraspManifold:
    """R of Eq. (11) for any hand: the grasp system F plus its principal-motion constraints.

    It implements the :class:`~sahgrasp.optimization.optimizer.GraspManifold` protocol, whose
    name it cannot share. ``SahGraspManifold``, its name before, still imports for one release
    with a DeprecationWarning.

    The atlas works in scaled coordinates ``y`` with ``x = scales * y`` (:meth:`x_of`): with
    :func:`coordinate_scales`, a unit of ``y`` in any direction moves the hand, the object or a
    contact by about the same distance, so that a chart radius means the same in every direction.
    ``F``, ``J``, :meth:`bounds`, :attr:`start`, :meth:`manipulability` and :meth:`check_charts`
    all take ``y``.

    Args:
        system: The feasible-grasp system F.
        motions: The principal hand motions (Section III), over ``x_h``.
        dimension: ``k``, 1 <= k <= t.
        start: The first grasp ``x_1`` (on F, inside the bounds) Eq. (13) passes through, in ``x``.
        obj: The object in the frame of the contact regions: chart centres where a link is inside
            it are no candidates and the free fingers are placed clear of it. None: only
            self-collision is checked.
        scales: ``x = scales * y``, (n,) positive; all ones (``y = x``) if None.

    Raises:
        GraspSystemError: ``dimension`` is not in ``[1, t]``, or ``scales`` is not n positive
            finite numbers.
    """

    def __init__(
        self,
        system: GraspSystem,
        motions: PrincipalMotions,
        dimension: int,
        start: FloatArray,
        obj: GraspObject | None = None,
        scales: ArrayLike | None = None,
    ) -> None:
        self.system = system
        self.motions = motions
        self.obj = obj
        self._dimension = dimension
        self.scales = np.ones(system.n) if scales is None else np.asarray(scales, np.float64)
        if self.scales.shape != (system.n,) or not np.all(
            np.isfinite(self.scales) & (self.scales > 0)
        ):
            raise GraspSystemError(f"scales must be {system.n} positive finite numbers")
        self._start = start / self.scales
        self._R, self._JR = reduced_system(system, motions, dimension, start)

    def x_of(self, y: ArrayLike) -> FloatArray:
        """The grasp-system coordinates ``x = scales * y`` of atlas points ``y`` (..., n)."""
        return np.asarray(y, dtype=np.float64) * self.scales

    def F(self, y: FloatArray) -> FloatArray:
        """``R(x)`` of Eq. (11) at ``x = scales * y``."""
        return self._R(self.x_of(y))

    def J(self, y: FloatArray) -> FloatArray:
        """Jacobian of :meth:`F` by ``y``."""
        return self._JR(self.x_of(y)) * self.scales

    @property
    def dimension(self) -> int:
        """``k``, the dimension of R."""
        return self._dimension

    @property
    def t(self) -> int:
        """Dimension of F."""
        return self.system.t

    @property
    def start(self) -> FloatArray:
        """The first grasp ``x_1``, in ``y``."""
        return self._start

    @property
    def retained_variance(self) -> float:
        """Share of the hand-motion variance the ``t - s`` kept motions explain."""
        return self.motions.retained_variance(self.system.t - self.dimension)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Joint limits and contact-region parameter ranges (in ``y``); the object pose is free."""
        return self.system.lower / self.scales, self.system.upper / self.scales

    def manipulability(self, y: FloatArray) -> Manipulability:
        """Ellipsoids of object twists reachable with unit actuated joint velocity (hard fingers).

        ``y`` is one grasp (n,) or a batch (..., n).
        """
        X = self.x_of(y)
        points = X.reshape(-1, self.system.n)
        C = np.array([self.system.hard_finger_constraints(p) for p in points])
        C = C.reshape(*X.shape[:-1], *C.shape[1:])
        a = len(self.system.actuated_rows)
        motions = null_space(C, C.shape[-1] - C.shape[-2])
        return ellipsoid_indices(motions[..., :a, :], motions[..., a:, :])

    def check_charts(self, centres: FloatArray, executor: Executor | None = None) -> ChartChecks:
        """Place the free fingers at every chart centre, then check self- and object collision.

        With an ``executor``, runs of consecutive centres are checked in its worker processes
        (each rebuilds the hand and the object once); the result is the same.
        """
        system = self.system
        centres = self.x_of(centres)
        configurations = np.array([system.configuration(x) for x in centres])
        configurations = configurations.reshape(len(centres), system.hand.nq)
        poses = np.array([system.object_pose(x).homogeneous for x in centres])
        check = _ChartCheck(
            system.hand.description, system.hand.description.digest(), self.obj,
            "" if self.obj is None else object_key(self.obj),
            free_fingers(system.hand, system.patches), tuple(c.finger for c in system.contacts),
        )  # fmt: skip
        if executor is None:
            return check.on(system.hand, self.obj, configurations, poses)
        count = max(min(len(centres), _CHECK_RUNS), -(-len(centres) // _CHECK_RUN_CENTRES))
        runs = np.array_split(np.arange(len(centres)), count)
        parts = executor.map(check, [configurations[r] for r in runs], [poses[r] for r in runs])
        return ChartChecks.joined(list(parts))


_CHECK_RUNS = 16
"""Runs of consecutive centres sent to the workers at least (one centre each, if fewer)."""
_CHECK_RUN_CENTRES = 256
"""Centres of a run at most (a run is a task of a few tenths of a second)."""


@dataclass(frozen=True)
class _ChartCheck:
    """The collision checks of chart centres, as plain values a worker process can rebuild.

    Attributes:
        description: The hand.
        digest: The hand description's digest (a worker refuses another hand).
        obj: The object, or None.
        obj_key: The object's content key (a worker keeps one copy per key).
        free: Fingers without a contact region, placed clear of everything.
        contacts: Fingers touching the object at their contacts.
    """

    description: HandDescription
    digest: str
    obj: GraspObject | None
    obj_key: str
    free: tuple[str, ...]
    contacts: tuple[str, ...]

    def __call__(self, configurations: FloatArray, poses: FloatArray) -> ChartChecks:
        """:meth:`on` with this worker's copies of the hand and the object."""
        hand = worker_hand(self.description, self.digest)
        obj = None if self.obj is None else worker_obstacle(self.obj, self.obj_key)
        assert not isinstance(obj, str)  # a GraspObject is kept as it came
        return self.on(hand, obj, configurations, poses)

    def on(
        self, hand: Hand, obj: GraspObject | None, configurations: FloatArray, poses: FloatArray
    ) -> ChartChecks:
        """Checks of ``configurations`` (N, nq), the object at ``poses`` (N, 4, 4) in the palm."""
        configurations = configurations.copy()
        object_collision = np.zeros(len(configurations), dtype=bool)
        if obj is not None:
            checker = checker_of(hand, obj)
            for i, T in enumerate(poses):  # palm at the origin: palm frame = world
                if self.free:
                    configurations[i] = checker.place_free_fingers(configurations[i], self.free,
                                                                   T_world_object=T).q  # fmt: skip
                # The verdict only, not the clearance: the search ends at the first penetration.
                object_collision[i] = checker.penetrated(configurations[i], self.contacts,
                                                         T_world_object=T)  # fmt: skip
        self_collision = np.array([hand.in_collision(q) for q in configurations], dtype=bool)
        return ChartChecks(configurations, self_collision, object_collision)


def coordinate_scales(
    system: GraspSystem, length_m: float, unit_m: float | None = None
) -> FloatArray:
    """``x = scales * y`` so that a unit of ``y`` moves something by about ``unit_m`` [m].

    Joint angles and the object's rotation vector [rad] get ``unit_m / length_m``: a unit turns a
    link of ``length_m`` (about a finger's length) through ``unit_m``. The object's translation
    [m] gets ``unit_m``. A contact parameter gets ``unit_m / |dO/dp|``, ``|dO/dp|`` being how far
    the contact point moves per unit of it at the regions' nominal parameters. ``unit_m``
    defaults to ``length_m`` (angles unscaled).

    Raises:
        GraspSystemError: ``length_m`` or ``unit_m`` is not a positive finite length.
    """
    unit = length_m if unit_m is None else unit_m
    for name, value in (("length_m", length_m), ("unit_m", unit)):
        if not (np.isfinite(value) and value > 0):
            raise GraspSystemError(f"{name} must be a positive finite length [m], got {value}")
    scales = np.full(system.n, unit / length_m)
    for contact in system.contacts:
        rates = np.linalg.norm(
            contact.region.evaluate(contact.region.nominal).point_jacobian, axis=0
        )
        scales[contact.params] = unit / np.where(rates > 0, rates, length_m)
    if system.free_object:
        start = system.pose_slice.start
        scales[start : start + 3] = unit
    return scales


MOTION_SOURCES = ("random", "grasps")
"""Where the principal motions come from: random hand poses, or solved grasps of the regions."""


def hand_motions(
    hand: Hand, system: GraspSystem, samples: int, seed: int, source: str = "random"
) -> PrincipalMotions:
    """PCA of hand configurations, restricted to ``x_h`` (Section III).

    Args:
        hand: The hand.
        system: The grasp system (its touching fingers' coordinates are ``x_h``).
        samples: Number of configurations sampled (``"grasps"``: IK problems posed).
        seed: Seed of the samples.
        source: ``"random"``: collision-free random hand configurations; ``"grasps"``: grasp
            postures, the IK's solutions of the regions' grasps at uniformly random contact
            parameters (the paper takes human grasp postures; these are the hand's own grasps of
            this object).

    Raises:
        OptimizationError: ``source`` is unknown, or fewer than two grasps were solved.
    """
    rng = np.random.default_rng(seed)
    if source == "random":
        draws = (hand.random_configuration(rng, collision_free=True) for _ in range(samples))
        X = [hand.finger_part(q) for q in draws]
    elif source == "grasps":
        X = _grasp_postures(hand, system.patches, samples, rng)
    else:
        raise OptimizationError(f"unknown motion source {source!r}; valid: {MOTION_SOURCES}")
    return principal_motions(np.array(X)[:, system.coordinates])


def _grasp_postures(
    hand: Hand, patches: GraspPatches, samples: int, rng: np.random.Generator
) -> list[FloatArray]:
    """Joint coordinates of the IK's solved grasps at random contact parameters."""
    free = free_fingers(hand, patches)
    postures = []
    for _ in range(samples):
        params = {f: rng.uniform(r.lower, r.upper) for f, r in patches.regions.items()}
        result = solve_ik(hand, patches.target(params), free_fingers=free)
        if result.success:
            postures.append(hand.finger_part(result.q))
    if len(postures) < 2:
        raise OptimizationError(
            f"{patches.name}: the IK solved {len(postures)} of {samples} grasps; need two or more"
        )
    return postures


def free_fingers(hand: Hand, patches: GraspPatches) -> tuple[str, ...]:
    """The fingers without a contact region: no part of F, placed clear of everything."""
    return tuple(f for f in hand.fingers if f not in patches.regions)


def first_grasp_system(
    hand: Hand,
    patches: GraspPatches,
    free_object: bool = True,
    symmetry_axis: ArrayLike | None = None,
    obj: GraspObject | None = None,
) -> GraspSystem:
    """F for ``hand`` and ``patches`` around the IK's grasp at the regions' nominal parameters.

    Fingers without a contact region are left free (they do not enter ``x``); given the object
    (in the regions' frame), they are placed clear of it and of the other links
    (``HandObjectClearance.place_free_fingers``). ``free_object`` and ``symmetry_axis`` are those
    of :class:`~sahgrasp.optimization.grasp.GraspSystem`.

    Raises:
        OptimizationError: The IK finds no such grasp.
    """
    free = free_fingers(hand, patches)
    first = solve_ik(hand, patches.target(), free_fingers=free)
    if not first.success:
        raise OptimizationError(f"{patches.name}: the IK found no first grasp ({first.reason})")
    q = first.q
    if obj is not None and free:  # the IK's world is the object frame
        q = HandObjectClearance(hand, obj.placed(np.eye(4))).place_free_fingers(q, free).q
    return GraspSystem(hand, patches, q, free_object, symmetry_axis)


def make_sah_manifold(
    hand: Hand,
    patches: GraspPatches,
    k: int = 2,
    free_object: bool = True,
    symmetry_axis: ArrayLike | None = None,
    obj: GraspObject | None = None,
    motion_samples: int = 2000,
    seed: int = 0,
    motion_source: str = "random",
    length_scale_m: float | None = None,
    unit_m: float | None = None,
) -> HandGraspManifold:
    """R for ``hand`` and the object's contact ``patches``, from the IK's first grasp.

    Args:
        hand: The hand.
        patches: Contact regions per finger in the object frame (fingers without one are free).
        k: Dimension of the relevant-grasp set R.
        free_object: Let the object pose vary (else it is fixed in the palm).
        symmetry_axis: Axis (object frame) about which every contact region is revolved: the
            object's spin about it, which changes nothing but the parametrisation, is left out.
        obj: The object, in the frame of ``patches`` (see :class:`HandGraspManifold`).
        motion_samples: Hand configurations sampled for the principal motions.
        seed: Seed of those samples.
        motion_source: Where they come from, one of :data:`MOTION_SOURCES` (see
            :func:`hand_motions`).
        length_scale_m: Scale the coordinates with :func:`coordinate_scales` at this length [m];
            None: the atlas works in ``x`` itself (radians and metres mixed).
        unit_m: What a unit of the scaled coordinates moves [m] (:func:`coordinate_scales`;
            default ``length_scale_m``); only with ``length_scale_m``.

    Raises:
        OptimizationError: The IK finds no first grasp, or it cannot be moved inside the bounds,
            or ``motion_source`` is unknown or gives too few grasps.
        GraspSystemError: ``k`` is not in ``[1, t]``.
    """
    system = first_grasp_system(hand, patches, free_object, symmetry_axis, obj)
    motions = hand_motions(hand, system, motion_samples, seed, motion_source)
    x1 = _start_inside(system.F, system.J, system.x_first, system.lower, system.upper)
    scales = None if length_scale_m is None else coordinate_scales(system, length_scale_m, unit_m)
    return HandGraspManifold(system, motions, k, x1, obj, scales)


def ik_seeds(problem: HandGraspManifold, count: int) -> FloatArray:
    """Seed grasps for :func:`~sahgrasp.optimization.optimizer.optimize_components`, (S, n).

    In the atlas's coordinates ``y``: ``x_1`` first, then the IK's solutions of the same contacts
    (the regions' nominal parameters) from ``count`` random starts (seeds 0..count-1); problems
    the IK did not solve are left out.
    """
    system = problem.system
    hand, patches = system.hand, system.patches
    free = free_fingers(hand, patches)
    seeds = [problem.start]
    for seed in range(count):
        settings = IKSettings(init="random", seed=seed)
        result = solve_ik(hand, patches.target(), settings, free_fingers=free)
        if result.success:
            seeds.append(system.point(result.q) / problem.scales)
    return np.array(seeds)


def _start_inside(
    F: Callable[[FloatArray], FloatArray],
    J: Callable[[FloatArray], FloatArray],
    x: FloatArray,
    lower: FloatArray,
    upper: FloatArray,
    margin: float = 1e-4,
) -> FloatArray:
    """The first grasp moved ``margin`` inside the box and back onto ``F = 0``.

    The IK leaves joints exactly at their limits, where the atlas's projection could step out of
    the box; coordinates moved inside stay fixed while Newton corrects the others, until all are
    inside.
    """
    inside = x.copy()
    free = np.ones(x.size, dtype=bool)
    for _ in range(10):
        clipped = np.clip(inside, lower + margin, upper - margin)
        free &= clipped == inside
        inside = clipped
        for _ in range(20):
            residual = F(inside)
            if np.linalg.norm(residual) < 1e-12:
                break
            inside[free] += np.linalg.lstsq(J(inside)[:, free], -residual, rcond=None)[0]
        if np.all((inside >= lower + margin) & (inside <= upper - margin)):
            return inside
    raise OptimizationError("the first grasp cannot be moved inside the joint and region bounds")


# ----- the grasp manifold on a mesh -------------------------------------------------------------
def mesh_patches(
    obj: GraspObject,
    target: GraspTarget,
    max_half_width_m: float = 0.02,
    tolerance_m: float = 3e-4,
    anchored: bool = False,
) -> GraspPatches:
    """Contact regions on a mesh object: the smooth local model around each contact.

    Args:
        obj: The object (its solids' meshes are the mesh), placed in the world.
        target: The contacts (world frame, on the placed object), one per touching finger.
        max_half_width_m: Largest half width of a region [m]
            (:func:`sahgrasp.objects.smooth_surface.fit_mesh_patch`).
        tolerance_m: Largest distance from a region's model to the mesh [m].
        anchored: Each model passes through its contact point with the contact's normal
            (``fit_mesh_patch(..., anchored=True)``), so a grasp reaching the contacts is on F.

    Returns:
        The regions, in the object frame.

    Raises:
        SurfaceModelError: No smooth model fits around a contact.
    """
    import trimesh

    mesh = obj.mesh()
    tm = trimesh.Trimesh(mesh.vertices_m, mesh.faces, process=False)
    T_object_world = np.linalg.inv(obj.T_world_object)
    regions: dict[str, ContactRegion] = {}
    for c in target.contacts:
        point = T_object_world[:3, :3] @ c.point + T_object_world[:3, 3]
        normal = T_object_world[:3, :3] @ c.normal
        regions[c.finger] = fit_mesh_patch(
            c.finger, tm, point, normal, max_half_width_m=max_half_width_m,
            tolerance_m=tolerance_m, anchored=anchored,
        )  # fmt: skip
    return GraspPatches(target.name, regions)


def make_mesh_manifold(
    hand: Hand,
    obj: GraspObject,
    target: GraspTarget,
    q_start: NDArray[np.float64] | None = None,
    k: int = 2,
    motion_samples: int = 2000,
    seed: int = 0,
    length_scale_m: float = 0.1,
    unit_m: float = 0.003,
    patches: GraspPatches | None = None,
) -> HandGraspManifold:
    """R (Eq. (11)) of a grasp of a mesh object, around a starting grasp.

    Each contact of ``target`` gets a smooth local model of the mesh (:func:`mesh_patches`); the
    fingers without a contact are free (placed clear of the object at every chart). The first
    grasp is ``q_start`` (world frame, the object at its placement), or the IK's solution of
    ``target`` with the object as an obstacle; it is moved onto F (its contacts onto the models)
    and inside the joint and region bounds by Newton's method. The atlas works in scaled
    coordinates (:func:`coordinate_scales`): a unit moves a contact or the object by about
    ``unit_m`` and turns a joint by ``unit_m / length_scale_m``.

    Raises:
        OptimizationError: The IK finds no first grasp, or it cannot be brought onto F inside
            the bounds.
        SurfaceModelError: No smooth model of the mesh fits around a contact.
        GraspSystemError: ``k`` is not in ``[1, t]``, or the scales are not positive lengths.
    """
    patches = patches or mesh_patches(obj, target)
    free = free_fingers(hand, patches)
    at_origin = obj.placed(np.eye(4))  # the IK's and the system's world: the object frame
    if q_start is None:
        first = solve_ik(hand, patches.target(), free_fingers=free, obstacle=at_origin)
        if not first.success:
            raise OptimizationError(
                f"{target.name}: the IK found no grasp of the start contacts ({first.reason})"
            )
        q = first.q.copy()
    else:
        q = hand.check_q(np.array(q_start, dtype=np.float64))
        T_object_palm = pin.SE3(np.linalg.inv(obj.T_world_object)) * hand.wrist_pose(q)
        hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(T_object_palm)
    if free:
        q = HandObjectClearance(hand, at_origin).place_free_fingers(q, free).q
    system = GraspSystem(hand, patches, q, free_object=True)
    motions = hand_motions(hand, system, motion_samples, seed, "random")
    x1 = _start_inside(system.F, system.J, system.x_first, system.lower, system.upper)
    scales = coordinate_scales(system, length_scale_m, unit_m)
    return HandGraspManifold(system, motions, k, x1, at_origin, scales)
