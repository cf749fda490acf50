"""The hold test: squeeze a grasp in MuJoCo, then pull the object in six directions.

Following DexGraspNet (Wang et al., ICRA 2023) and BODex (Chen, Ke, Wang, ICRA 2025), the wrist
is fixed at the grasp's pose and gravity is off; the fingers touching the object squeeze it with
a balanced set of forces, then a force of ``mass x 9.81 N`` pulls the object for ``pull_s`` in
each of +-x, +-y, +-z (world axes), each pull from the same settled state. The grasp holds if
the object's centre of mass moves less than ``max_displacement_m`` and the object turns less
than ``max_rotation_deg`` during every pull (and while settling); BODex's verdict uses its own
thresholds (50 mm, 15 deg). A pull ends early once the object has come to rest under it (a damped
model at rest under a constant force stays at rest). docs/methods/physics.md gives the model and
every parameter.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import nnls

from sahgrasp.ik import IKResult
from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject
from sahgrasp.sim.model import SimModel, build_model
from sahgrasp.sim.settings import DIRECTIONS, HoldSettings

__all__ = [
    "REASONS",
    "DirectionResult",
    "HoldResult",
    "HoldTester",
    "Squeeze",
    "balanced_forces",
    "hold_test",
]

REASONS = (
    "holds",
    "no contact",
    "moved while settling",
    "slips",
    "turns",
    "unstable simulation",
)
"""Values of :attr:`HoldResult.reason`: why a grasp fails (``holds`` when it does not)."""

_CHUNK_S = 0.02
"""Simulated time [s] between two checks of the object's motion (early exit on failure)."""
_EDGES = 4
"""Edges of the linearised friction cone the squeeze may use to balance its forces."""
_REST_WINDOW_S = 0.1
"""Simulated time [s] over which a pull's object speed is measured for the early end at rest."""
_REST_SPEED_M_S = 1e-3
"""The object is at rest below this speed [m/s] (and :data:`_REST_SPEED_DEG_S`)."""
_REST_SPEED_DEG_S = 1.0
"""The object is at rest below this angular speed [deg/s] (and :data:`_REST_SPEED_M_S`)."""


@dataclass(frozen=True)
class DirectionResult:
    """The object's motion under one pull.

    Attributes:
        direction: ``+x``, ``-x``, ``+y``, ``-y``, ``+z`` or ``-z`` (world axes).
        displacement_m: Largest distance [m] of the centre of mass from its settled position.
        rotation_deg: Largest angle [deg] the object turned from its settled orientation.
        holds: Both below the test's thresholds.
        holds_bodex: Both below BODex's thresholds.
        simulated_s: Simulated time [s] of the pull (less than ``pull_s`` when it stopped early:
            the object had already left both thresholds, or had come to rest,
            ``HoldSettings.stop_at_rest``).
    """

    direction: str
    displacement_m: float
    rotation_deg: float
    holds: bool
    holds_bodex: bool
    simulated_s: float

    def to_dict(self) -> dict[str, Any]:
        """JSON entry (docs/methods/physics.md)."""
        return {
            "direction": self.direction,
            "displacement_m": self.displacement_m,
            "rotation_deg": self.rotation_deg,
            "holds": self.holds,
            "holds_bodex": self.holds_bodex,
            "simulated_s": self.simulated_s,
        }


@dataclass(frozen=True)
class Squeeze:
    """The balanced squeeze: contact fingers, forces and what the servos are told.

    Attributes:
        fingers: The contact fingers (fingertip within ``contact_distance_m`` of the object).
        points_m: Contact points, palm frame (F, 3) [m].
        normals: Inward unit normals (into the object), palm frame (F, 3).
        gaps_m: Signed fingertip-object distance the simulator sees (F,) [m], negative inside.
        forces_n: Contact force of each finger on the object, palm frame (F, 3) [N].
        imbalance_n: Norm of the forces' sum [N] (0: the squeeze alone does not push).
        imbalance_nm: Norm of their moment about the centre of mass [N m].
        torque_limited: Some joint needs more than its torque limit to squeeze.
    """

    fingers: tuple[str, ...]
    points_m: NDArray[np.float64]
    normals: NDArray[np.float64]
    gaps_m: NDArray[np.float64]
    forces_n: NDArray[np.float64]
    imbalance_n: float
    imbalance_nm: float
    torque_limited: bool

    @property
    def normal_forces_n(self) -> NDArray[np.float64]:
        """Normal component of each finger's force [N]."""
        return np.einsum("ij,ij->i", self.forces_n, self.normals)


@dataclass(frozen=True)
class HoldResult:
    """Outcome of the hold test of one grasp.

    Attributes:
        name: The grasp's name.
        holds: The object moved less than ``max_displacement_m`` and turned less than
            ``max_rotation_deg`` while settling and under every pull.
        holds_bodex: The same with BODex's thresholds.
        reason: One of :data:`REASONS`; ``slips`` and ``turns`` name the direction in
            ``detail``.
        detail: One line saying why the grasp fails (empty when it holds).
        directions: Per pull, in the order of :data:`~sahgrasp.sim.settings.DIRECTIONS`.
        initial_penetration_m: Deepest hand-object overlap [m] the simulator sees before
            anything moves (0: none).
        penetrating_geom: The hand geom of that overlap, or None.
        settle_displacement_m: Distance [m] the centre of mass moved while settling.
        settle_rotation_deg: Angle [deg] the object turned while settling.
        mass_kg: Object mass [kg] (the pull is ``mass_kg * gravity_m_s2``).
        contact_fingers: Fingers that squeeze.
        squeeze_normal_n: Normal force [N] each contact finger is asked for.
        squeeze_imbalance_n: Norm of the squeeze forces' sum [N].
        squeeze_imbalance_nm: Norm of their moment about the centre of mass [N m].
        torque_limited: Some joint needs more than its torque limit to squeeze.
        simulated_s: Simulated time [s] in all.
        time_s: Wall time [s] of the test (the model built before excluded).
    """

    name: str
    holds: bool
    holds_bodex: bool
    reason: str
    detail: str
    directions: tuple[DirectionResult, ...]
    initial_penetration_m: float
    penetrating_geom: str | None
    settle_displacement_m: float
    settle_rotation_deg: float
    mass_kg: float
    contact_fingers: tuple[str, ...]
    squeeze_normal_n: tuple[float, ...]
    squeeze_imbalance_n: float
    squeeze_imbalance_nm: float
    torque_limited: bool
    simulated_s: float
    time_s: float = field(compare=False)

    def to_dict(self) -> dict[str, Any]:
        """JSON entry of ``sahgrasp check`` (docs/methods/physics.md), SI units."""
        return {
            "name": self.name,
            "holds": self.holds,
            "holds_bodex": self.holds_bodex,
            "reason": self.reason,
            "detail": self.detail,
            "directions": [d.to_dict() for d in self.directions],
            "initial_penetration_m": self.initial_penetration_m,
            "penetrating_geom": self.penetrating_geom,
            "settle_displacement_m": self.settle_displacement_m,
            "settle_rotation_deg": self.settle_rotation_deg,
            "mass_kg": self.mass_kg,
            "contact_fingers": list(self.contact_fingers),
            "squeeze_normal_n": list(self.squeeze_normal_n),
            "squeeze_imbalance_n": self.squeeze_imbalance_n,
            "squeeze_imbalance_nm": self.squeeze_imbalance_nm,
            "torque_limited": self.torque_limited,
            "simulated_s": self.simulated_s,
            "time_s": self.time_s,
        }


def _tangents(n: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(n, helper)
    t1 /= np.linalg.norm(t1)
    return t1, np.cross(n, t1)


def _motion(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float]:
    """Distance [m] and angle [deg] between two poses (x, y, z, then quaternion w, x, y, z)."""
    distance = math.sqrt((b[0] - a[0]) ** 2 + (b[1] - a[1]) ** 2 + (b[2] - a[2]) ** 2)
    dot = min(1.0, abs(b[3] * a[3] + b[4] * a[4] + b[5] * a[5] + b[6] * a[6]))
    return distance, math.degrees(2.0 * math.acos(dot))


def balanced_forces(
    points_m: NDArray[np.float64],
    normals: NDArray[np.float64],
    centre_m: NDArray[np.float64],
    size_m: float,
    squeeze_n: float,
    friction: float,
) -> NDArray[np.float64]:
    """Contact forces (F, 3) [N] whose sum and moment vanish, mean normal force ``squeeze_n``.

    Non-negative least squares (scipy's NNLS) over each finger's inward normal and the edges of
    its friction cone of coefficient ``friction`` (linearised, :data:`_EDGES` edges), weighted
    so that it balances first (net force and moment, the moment divided by ``size_m``), keeps
    the mean normal force, then keeps each finger near ``squeeze_n`` and uses friction least.
    """
    count = len(points_m)
    columns, finger_of, is_edge = [], [], []
    for i in range(count):
        n = normals[i]
        directions = [n]
        if friction > 0:
            t1, t2 = _tangents(n)
            for k in range(_EDGES):
                angle = 2.0 * math.pi * k / _EDGES
                directions.append(n + friction * (math.cos(angle) * t1 + math.sin(angle) * t2))
        for d in directions:
            columns.append(d)
            finger_of.append(i)
            is_edge.append(d is not n)
    D = np.array(columns)  # (K, 3), each with normal component 1
    arms = points_m[np.array(finger_of)] - centre_m
    W = np.vstack([D.T, np.cross(arms, D).T / size_m])  # (6, K)
    K = len(D)
    owner = np.zeros((count, K))
    owner[np.array(finger_of), np.arange(K)] = 1.0
    A = np.vstack([
        10.0 * W,
        10.0 * np.ones((1, K)) / count,  # the mean normal force
        owner,  # each finger near the mean
        0.5 * np.diag(np.array(is_edge, dtype=np.float64)),  # friction used least
    ])  # fmt: skip
    b = np.concatenate([np.zeros(6), [10.0 * squeeze_n], np.full(count, squeeze_n), np.zeros(K)])
    weights, _ = nnls(A, b, maxiter=50 * K)
    return np.asarray(owner @ (weights[:, None] * D), dtype=np.float64)


class HoldTester:
    """The hold test of grasps of one object by one hand; the model is compiled once.

    Args:
        hand: The hand.
        obj: The object, at its placement in the world.
        settings: The test's parameters (defaults: :class:`HoldSettings`).
    """

    def __init__(self, hand: Hand, obj: GraspObject, settings: HoldSettings | None = None) -> None:
        self.hand = hand
        self.obj = obj
        self.settings = settings or HoldSettings()
        self.sim: SimModel = build_model(hand, obj, self.settings)
        m = self.sim.model
        self._state_spec = mujoco.mjtState.mjSTATE_INTEGRATION
        self._state = np.empty(mujoco.mj_stateSize(m, self._state_spec))
        self._tip_geoms = {g: f for f, ids in self.sim.fingertip_geoms.items() for g in ids}
        self._object_geoms = set(np.flatnonzero(m.geom_bodyid == self.sim.object_body).tolist())
        self._chunk = max(1, round(_CHUNK_S / m.opt.timestep))
        self._offsets = np.zeros(m.nu)

    # ----- set-up --------------------------------------------------------------------------------
    def _place(self, q: NDArray[np.float64]) -> None:
        """Reset the data to the grasp: joint angles, object pose in the palm frame, servos."""
        sim, m, d = self.sim, self.sim.model, self.sim.data
        mujoco.mj_resetData(m, d)
        joints = self.hand.joint_values(q)
        for name, adr in zip(sim.joint_names, sim.qpos_addresses, strict=True):
            d.qpos[adr] = joints[name]
        T_world_palm = self.hand.wrist_pose(q)
        T_world_object = pin.SE3(self.obj.T_world_object[:3, :3], self.obj.T_world_object[:3, 3])
        T_palm_object = T_world_palm.inverse() * T_world_object
        quat = pin.Quaternion(T_palm_object.rotation).coeffs()
        a = sim.object_qpos
        d.qpos[a : a + 3] = T_palm_object.translation
        d.qpos[a + 3 : a + 7] = [quat[3], quat[0], quat[1], quat[2]]
        d.ctrl[:] = [joints[name] for name in sim.actuated]

    def _contacts(self) -> tuple[dict[str, tuple[float, NDArray[np.float64], NDArray[np.float64]]],
                                 float, str | None]:  # fmt: skip
        """Fingertip-object pairs within ``contact_distance_m`` and the deepest overlap.

        One collision pass with the fingertips' margin raised to ``contact_distance_m`` (and
        put back): per finger its nearest pair (distance [m], midpoint, inward normal).
        """
        sim, m, d = self.sim, self.sim.model, self.sim.data
        tips = np.array(list(self._tip_geoms), dtype=np.intp)
        m.geom_margin[tips] = self.settings.contact_distance_m
        try:
            mujoco.mj_fwdPosition(m, d)
        finally:
            m.geom_margin[tips] = 0.0
        nearest: dict[str, tuple[float, NDArray[np.float64], NDArray[np.float64]]] = {}
        depth, deepest = 0.0, None
        for c in d.contact[: d.ncon]:
            g1, g2, dist = int(c.geom1), int(c.geom2), float(c.dist)
            hand_geom = g2 if g1 in self._object_geoms else g1
            if dist < -depth:
                depth, deepest = -dist, sim.geom_names[hand_geom]
            finger = self._tip_geoms.get(hand_geom)
            if finger is None or dist > self.settings.contact_distance_m:
                continue
            normal = np.array(c.frame[:3])  # from geom1 to geom2
            if g1 in self._object_geoms:
                normal = -normal
            if finger not in nearest or dist < nearest[finger][0]:
                nearest[finger] = (dist, np.array(c.pos), normal)
        return nearest, depth, deepest

    def contact_jacobian(
        self, fingers: tuple[str, ...], points_m: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """Jacobian (3F, actuators) of points fixed to the fingertips w.r.t. the servoed joints.

        At the model's current state; ``points_m`` (F, 3) in the palm frame [m]. A coupled joint
        turns with its leader, so its column is folded into the leader's (times the multiplier):
        the columns are the joints the servos move.
        """
        sim, m, d = self.sim, self.sim.model, self.sim.data
        J = np.zeros((3 * len(fingers), m.nu))
        jacp = np.zeros((3, m.nv))
        for i, f in enumerate(fingers):
            mujoco.mj_jac(m, d, jacp, None, points_m[i], sim.fingertip_bodies[f])
            block = jacp[:, sim.actuated_dofs].copy()
            for dof, leader, multiplier in sim.mimic:
                block[:, leader] += multiplier * jacp[:, dof]
            J[3 * i : 3 * i + 3] = block
        return J

    def squeeze(
        self, q: ArrayLike, fingers: tuple[str, ...] | None = None
    ) -> tuple[Squeeze, NDArray[np.float64], float, str | None]:
        """The balanced squeeze of grasp ``q`` and the servo targets that apply it.

        ``fingers``: the grasp's contact fingers when it says which (a planned grasp); a finger
        it leaves free does not squeeze even when its fingertip is near the object. None: every
        finger within ``contact_distance_m``.

        The targets are the contact configuration (each fingertip moved along its normal by its
        gap, least squares over its joints) plus ``K^-1 J^T f``: at the contact configuration
        the servos' torques are exactly those that press with the forces ``f``.

        Returns:
            The squeeze, the servo targets [rad] (actuator order), the initial penetration [m]
            and the hand geom of it (None without overlap).
        """
        q = self.hand.check_q(q)
        self._place(q)
        sim, m, d = self.sim, self.sim.model, self.sim.data
        nearest, depth, deepest = self._contacts()
        chosen = tuple(
            f for f in self.hand.fingers if f in nearest and (fingers is None or f in fingers)
        )
        targets = np.array(d.ctrl, dtype=np.float64)
        if not chosen:
            empty = np.zeros((0, 3))
            self._offsets = np.zeros(m.nu)
            return (
                Squeeze((), empty, empty, np.zeros(0), empty, 0.0, 0.0, False),
                targets,
                depth,
                deepest,
            )
        gaps = np.array([nearest[f][0] for f in chosen])
        points = np.array([nearest[f][1] for f in chosen])
        normals = np.array([nearest[f][2] for f in chosen])
        centre = np.array(d.xipos[sim.object_body])
        s = self.settings
        forces = balanced_forces(points, normals, centre, sim.size_m, s.squeeze_n,
                                 s.balance_friction * s.friction)  # fmt: skip
        net = forces.sum(axis=0)
        moment = np.cross(points - centre, forces).sum(axis=0)
        J = self.contact_jacobian(chosen, points)
        moves = (gaps[:, None] * normals).ravel()
        close = np.linalg.lstsq(J, moves, rcond=1e-6)[0]
        torques = J.T @ forces.ravel()
        limits = m.actuator_forcerange[:, 1]
        self._offsets = torques / s.stiffness_nm_rad
        targets = targets + close + self._offsets
        squeeze = Squeeze(
            chosen, points, normals, gaps, forces, float(np.linalg.norm(net)),
            float(np.linalg.norm(moment)), bool(np.any(np.abs(torques) > limits)),
        )  # fmt: skip
        return squeeze, targets, depth, deepest

    # ----- the test ------------------------------------------------------------------------------
    def _pose(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        d, sim = self.sim.data, self.sim
        a = sim.object_qpos
        return np.array(d.xipos[sim.object_body]), np.array(d.qpos[a + 3 : a + 7])

    def _run(self, seconds: float, start: tuple[NDArray[np.float64], NDArray[np.float64]],
             stop: tuple[float, float],
             ramp: tuple[NDArray[np.float64], NDArray[np.float64], int] | None = None,
             rest: tuple[float, float] | None = None,
             ) -> tuple[float, float, float, bool]:  # fmt: skip
        """Step ``seconds``; the largest motion from ``start`` (displacement [m], angle [deg]).

        Stops early once the motion passes ``stop`` (displacement, angle). ``ramp`` (from,
        to, steps): the servo targets go linearly from ``from`` to ``to`` over the first
        ``steps`` steps. ``rest`` (displacement [m], angle [deg], the smaller thresholds): stops
        early once the object is at rest (:data:`_REST_SPEED_M_S`, :data:`_REST_SPEED_DEG_S`
        over the last :data:`_REST_WINDOW_S`, path lengths sampled every :data:`_CHUNK_S`) and
        even at that speed until the end it would stay below half of each threshold. Returns
        the two maxima, the simulated time and whether the simulation stayed trustworthy
        (finite accelerations, no contact dropped for want of memory).
        """
        m, d = self.sim.model, self.sim.data
        steps = max(1, round(seconds / m.opt.timestep))
        done, moved, turned = 0, 0.0, 0.0
        # Views and plain floats: this loop runs some 300 times per grasp.
        centre = d.xipos[self.sim.object_body]
        a = self.sim.object_qpos
        quat = d.qpos[a + 3 : a + 7]
        origin = (*(float(v) for v in start[0]), *(float(v) for v in start[1]))
        bad_qacc = d.warning[mujoco.mjtWarning.mjWARN_BADQACC]
        full = d.warning[mujoco.mjtWarning.mjWARN_CNSTRFULL]  # contacts dropped: not trusted
        window = max(1, round(_REST_WINDOW_S / (self._chunk * m.opt.timestep)))
        path: list[tuple[float, float]] = []  # per chunk: distance [m] and angle [deg] moved
        last = origin
        while done < steps:
            n = min(self._chunk, steps - done)
            if ramp is not None and done < ramp[2]:
                # The targets move every step while the grip closes: jumps of the targets
                # would jerk the fingers, and stiff friction carries a jerk into the object.
                for k in range(n):
                    d.ctrl[:] = ramp[0] + min(1.0, (done + k + 1) / ramp[2]) * (ramp[1] - ramp[0])
                    mujoco.mj_step(m, d)
            else:
                if ramp is not None:
                    d.ctrl[:] = ramp[1]
                mujoco.mj_step(m, d, n)
            done += n
            if bad_qacc.number > 0 or full.number > 0:
                return moved, turned, done * m.opt.timestep, False
            pose = (*centre.tolist(), *quat.tolist())
            distance, angle = _motion(origin, pose)
            moved, turned = max(moved, distance), max(turned, angle)
            if moved >= stop[0] or turned >= stop[1]:
                break
            if rest is not None:
                path.append(_motion(last, pose))
                last = pose
                if len(path) >= 2 * window:
                    # The object is damped and the pull constant: once it rests, it stays.
                    span = window * self._chunk * m.opt.timestep
                    speed = sum(p[0] for p in path[-window:]) / span
                    spin = sum(p[1] for p in path[-window:]) / span
                    left = (steps - done) * m.opt.timestep
                    if (
                        speed < _REST_SPEED_M_S
                        and spin < _REST_SPEED_DEG_S
                        and moved + speed * left < 0.5 * rest[0]
                        and turned + spin * left < 0.5 * rest[1]
                    ):
                        break
        return moved, turned, done * m.opt.timestep, True

    def test(
        self,
        grasp: IKResult | ArrayLike,
        name: str = "",
        fingers: tuple[str, ...] | None = None,
    ) -> HoldResult:
        """Hold-test one grasp: an IK result or a configuration ``q`` of the hand.

        The object is at its placement (``obj.T_world_object``), the wrist at the grasp's pose.
        ``fingers``: the grasp's contact fingers when it names them (a planned grasp: its free
        fingers do not squeeze); None: every fingertip within ``contact_distance_m``.
        """
        started = time.perf_counter()
        if isinstance(grasp, IKResult):
            name = name or grasp.name
            q = grasp.q
        else:
            q = np.asarray(grasp, dtype=np.float64)
        s, sim, m, d = self.settings, self.sim, self.sim.model, self.sim.data
        squeeze, targets, depth, deepest = self.squeeze(q, fingers)
        squeeze_offsets = self._offsets
        base = dict(
            name=name, initial_penetration_m=depth, penetrating_geom=deepest,
            mass_kg=sim.mass_kg, contact_fingers=squeeze.fingers,
            squeeze_normal_n=tuple(float(x) for x in squeeze.normal_forces_n),
            squeeze_imbalance_n=squeeze.imbalance_n, squeeze_imbalance_nm=squeeze.imbalance_nm,
            torque_limited=squeeze.torque_limited,
        )  # fmt: skip

        def explained(detail: str) -> str:
            if depth <= 1e-3 or not detail:
                return detail
            return (f"{detail}; at the start {deepest} is {depth * 1e3:.1f} mm inside the "
                    "object")  # fmt: skip

        def finish(reason: str, detail: str, directions: tuple[DirectionResult, ...],
                   settle: tuple[float, float], simulated: float, holds: bool,
                   holds_bodex: bool) -> HoldResult:  # fmt: skip
            return HoldResult(
                reason=reason, detail=explained(detail), directions=directions, holds=holds,
                holds_bodex=holds_bodex, settle_displacement_m=settle[0],
                settle_rotation_deg=settle[1], simulated_s=simulated,
                time_s=time.perf_counter() - started, **base,  # type: ignore[arg-type]
            )  # fmt: skip

        if not squeeze.fingers:
            detail = f"no fingertip within {s.contact_distance_m * 1e3:g} mm of the object"
            return finish("no contact", detail, (), (0.0, 0.0), 0.0, False, False)
        self._place(q)
        mujoco.mj_forward(m, d)
        start = self._pose()
        stop = (s.bodex_displacement_m, max(s.max_rotation_deg, s.bodex_rotation_deg))
        # The grip closes gradually over the first half of the settling, as a controller
        # closes it: servos loaded at once would kick a light object before all fingers press.
        ramp = (targets - squeeze_offsets, targets, round(0.5 * s.settle_s / s.timestep_s))
        moved, turned, simulated, finite = self._run(s.settle_s, start, stop, ramp)
        settle = (moved, turned)
        if not finite:
            return finish("unstable simulation", "the simulation diverged while settling", (),
                          settle, simulated, False, False)  # fmt: skip
        settled_ok = moved < s.max_displacement_m and turned < s.max_rotation_deg
        settled_bodex = moved < s.bodex_displacement_m and turned < s.bodex_rotation_deg
        if not settled_bodex:
            detail = (f"the squeeze moved the object {moved * 1e3:.1f} mm and turned it "
                      f"{turned:.1f} deg before any pull")  # fmt: skip
            return finish("moved while settling", detail, (), settle, simulated, False, False)
        settled = self._pose()
        mujoco.mj_getState(m, d, self._state, self._state_spec)
        weight = sim.mass_kg * s.gravity_m_s2
        R_world_palm = self.hand.wrist_pose(q).rotation
        # A pull may end at rest only where both verdicts are then sure.
        at_rest = (
            (min(s.max_displacement_m, s.bodex_displacement_m),
             min(s.max_rotation_deg, s.bodex_rotation_deg))
            if s.stop_at_rest else None
        )  # fmt: skip
        results: list[DirectionResult] = []
        for label, axis in DIRECTIONS:
            if label not in s.directions:
                continue
            mujoco.mj_setState(m, d, self._state, self._state_spec)
            d.xfrc_applied[sim.object_body, :3] = weight * (R_world_palm.T @ np.array(axis))
            moved, turned, seconds, finite = self._run(s.pull_s, settled, stop, rest=at_rest)
            d.xfrc_applied[sim.object_body, :3] = 0.0
            simulated += seconds
            if not finite:
                return finish("unstable simulation", f"the simulation diverged pulling {label}",
                              tuple(results), settle, simulated, False, False)  # fmt: skip
            results.append(DirectionResult(
                label, moved, turned,
                moved < s.max_displacement_m and turned < s.max_rotation_deg,
                moved < s.bodex_displacement_m and turned < s.bodex_rotation_deg, seconds,
            ))  # fmt: skip
            if s.stop_at_first_failure and not results[-1].holds:
                break
        complete = len(results) == len(s.directions)
        holds = settled_ok and complete and all(r.holds for r in results)
        holds_bodex = complete and all(r.holds_bodex for r in results)
        if holds:
            return finish("holds", "", tuple(results), settle, simulated, True, True)
        if not settled_ok:
            detail = (f"the squeeze moved the object {settle[0] * 1e3:.1f} mm and turned it "
                      f"{settle[1]:.1f} deg before any pull")  # fmt: skip
            return finish("moved while settling", detail, tuple(results), settle, simulated,
                          False, holds_bodex)  # fmt: skip
        worst = next(r for r in results if not r.holds)
        if worst.displacement_m >= s.max_displacement_m:
            reason = "slips"
            detail = (
                f"pulled {worst.direction}, the object moved "
                f"{worst.displacement_m * 1e3:.1f} mm (limit {s.max_displacement_m * 1e3:g})"
            )
        else:
            reason = "turns"
            detail = (
                f"pulled {worst.direction}, the object turned {worst.rotation_deg:.1f} deg "
                f"(limit {s.max_rotation_deg:g})"
            )
        return finish(reason, detail, tuple(results), settle, simulated, False, holds_bodex)


def hold_test(
    hand: Hand,
    grasp: IKResult | ArrayLike,
    obj: GraspObject,
    settings: HoldSettings | None = None,
) -> HoldResult:
    """Hold-test one grasp of ``obj`` (builds the model; use :class:`HoldTester` for many).

    Args:
        hand: The hand.
        grasp: An :class:`~sahgrasp.ik.IKResult` or a configuration ``q`` (wrist pose then
            joint coordinates, see :class:`~sahgrasp.model.hand.Hand`); build one from a wrist pose
            and joint values with :meth:`~sahgrasp.model.hand.Hand.configuration`.
        obj: The object at its placement in the world.
        settings: The test's parameters.
    """
    return HoldTester(hand, obj, settings).test(grasp)
