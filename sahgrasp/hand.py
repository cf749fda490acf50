"""The hand model: one Pinocchio model for any hand URDF, with virtual fingertip-contact joints.

``load_hand`` builds, from a URDF and a small :class:`HandDescription`:

* a free-flyer root joint ``wrist`` (the palm pose in ``world``, 6 DoF);
* the URDF joints, with ``<mimic>`` joints honoured by Pinocchio (they carry no coordinate of their
  own, so every computation -- kinematics, Jacobians, integration, sampling, limits -- is in the
  independent coordinates);
* two virtual revolute joints per fingertip, ``<finger>_contact_pitch`` (from the fingertip axis
  towards the pad) and ``<finger>_contact_yaw`` (sideways), placing the contact point on the
  fingertip sphere of radius ``R`` (ik-initial-sequence Section 2, Fig. 2b); the contact frame's
  x axis is the fingertip's outward normal at the contact point;
* the coal self-collision model of the URDF collision shapes.

For the SAH this is the paper's 27 DoF: 6 wrist + 13 finger + 8 virtual.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from importlib import metadata, resources
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from sahgrasp.collision import SelfCollision
from sahgrasp.errors import HandModelError, InvalidConfigurationError

__all__ = [
    "BUILTIN_HANDS",
    "ContactJacobians",
    "ContactState",
    "FingerSpec",
    "Hand",
    "HandDescription",
    "allegro_description",
    "load_hand",
    "sah_description",
]

BUILTIN_HANDS = ("sah", "allegro")
"""Hand names that ``load_hand`` knows without a description file."""

_DEG = math.pi / 180.0
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class FingerSpec:
    """A finger as the hand description names it.

    Attributes:
        name: ``thumb``, ``index``, ``middle``, ``ring`` (or any name for another hand).
        tip_link: URDF link whose origin is the fingertip-sphere centre.
        tip_axis: Unit vector in ``tip_link``'s frame along the fingertip (virtual angles zero).
        pad_axis: Unit vector in ``tip_link``'s frame towards the pad, orthogonal to ``tip_axis``.
    """

    name: str
    tip_link: str
    tip_axis: tuple[float, float, float]
    pad_axis: tuple[float, float, float]


@dataclass(frozen=True)
class HandDescription:
    """What sahgrasp needs beyond the URDF to model a hand.

    Attributes:
        name: Short name (``sah``, ``allegro``, ...).
        urdf_path: The hand URDF.
        fingers: The fingers, in the order results list them.
        fingertip_radius_m: Radius ``R`` of the fingertip spheres [m].
        contact_pitch_limits_rad: Accepted contact region from the fingertip axis towards the pad.
        contact_yaw_limits_rad: Accepted contact region sideways.
        excluded_collisions: Link-name pairs whose contact is by design (never checked).
        package_dirs: Folders where ``package://`` mesh URIs of the URDF are resolved.
    """

    name: str
    urdf_path: Path
    fingers: tuple[FingerSpec, ...]
    fingertip_radius_m: float
    contact_pitch_limits_rad: tuple[float, float]
    contact_yaw_limits_rad: tuple[float, float]
    excluded_collisions: tuple[tuple[str, str], ...] = ()
    package_dirs: tuple[Path, ...] = field(default_factory=tuple)

    @property
    def finger_names(self) -> tuple[str, ...]:
        """Finger names in order."""
        return tuple(f.name for f in self.fingers)

    def digest(self) -> str:
        """SHA-256 of the kinematic description (URDF text and this description, not paths)."""
        h = hashlib.sha256(self.urdf_path.read_bytes())
        h.update(json.dumps(self._kinematic_fields(), sort_keys=True).encode())
        return h.hexdigest()

    def _kinematic_fields(self) -> dict[str, Any]:
        return {
            "fingers": [[f.name, f.tip_link, f.tip_axis, f.pad_axis] for f in self.fingers],
            "fingertip_radius_m": self.fingertip_radius_m,
            "contact_pitch_limits_rad": self.contact_pitch_limits_rad,
            "contact_yaw_limits_rad": self.contact_yaw_limits_rad,
        }

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> HandDescription:
        """Read a hand description file; its ``urdf`` is relative to the file's folder.

        The file holds ``name``, ``urdf``, ``fingertip_radius_m``, ``contact_pitch_limits_rad``,
        ``contact_yaw_limits_rad``, ``fingers`` (a list of ``{"name", "tip_link", "tip_axis",
        "pad_axis"}``) and optionally ``excluded_collisions`` and ``package_dirs``.
        """
        path = Path(path)
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            folder = path.parent
            return cls(
                name=str(data["name"]),
                urdf_path=folder / data["urdf"],
                fingers=tuple(
                    FingerSpec(
                        f["name"], f["tip_link"], _unit3(f["tip_axis"]), _unit3(f["pad_axis"])
                    )
                    for f in data["fingers"]
                ),
                fingertip_radius_m=float(data["fingertip_radius_m"]),
                contact_pitch_limits_rad=_pair(data["contact_pitch_limits_rad"]),
                contact_yaw_limits_rad=_pair(data["contact_yaw_limits_rad"]),
                excluded_collisions=tuple(
                    (str(a), str(b)) for a, b in data.get("excluded_collisions", [])
                ),
                package_dirs=tuple(folder / p for p in data.get("package_dirs", [])),
            )
        except OSError as exc:
            raise HandModelError(f"cannot read hand description {path}: {exc.strerror}") from exc
        except (ValueError, KeyError, TypeError) as exc:
            raise HandModelError(
                f"hand description {path} is malformed ({type(exc).__name__}: {exc}); it needs "
                "name, urdf, fingertip_radius_m, contact_pitch_limits_rad, "
                "contact_yaw_limits_rad and fingers [{name, tip_link, tip_axis, pad_axis}]"
            ) from exc


def _unit3(values: Sequence[float]) -> tuple[float, float, float]:
    vec = np.asarray(values, dtype=float)
    if vec.shape != (3,) or not np.all(np.isfinite(vec)) or np.linalg.norm(vec) == 0.0:
        raise ValueError(f"axis must be 3 finite numbers, not all zero, got {values!r}")
    vec = vec / np.linalg.norm(vec)
    return (float(vec[0]), float(vec[1]), float(vec[2]))


def _pair(values: Sequence[float]) -> tuple[float, float]:
    lo, hi = (float(v) for v in values)
    if not lo < hi:
        raise ValueError(f"limits must be [lower, upper] with lower < upper, got {values!r}")
    return (lo, hi)


def sah_description() -> HandDescription:
    """The right Schunk Anthropomorphic Hand (``urdf/sah_right.urdf``, sah-kinematics.md).

    The fingertip sphere has radius 10 mm, centred 29.5 mm along the distal phalanx, as in the
    IK model of the paper's lab; the accepted contact region is -15..80 deg towards the pad and
    -35..35 deg sideways (ik-initial-sequence Fig. 2b).
    """
    urdf = resources.files("sahgrasp") / "urdf" / "sah_right.urdf"
    fingers = tuple(
        FingerSpec(name, f"{name}_tip", (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))
        for name in ("thumb", "index", "middle", "ring")
    )
    return HandDescription(
        name="sah",
        urdf_path=Path(str(urdf)),
        fingers=fingers,
        fingertip_radius_m=0.010,
        contact_pitch_limits_rad=(-15 * _DEG, 80 * _DEG),
        contact_yaw_limits_rad=(-35 * _DEG, 35 * _DEG),
        excluded_collisions=(
            *(("palm", f"{f}_base") for f in ("index", "middle", "ring")),
            ("thumb_base", "thumb_proximal"),
        ),
    )


def allegro_description() -> HandDescription:
    """The right Allegro hand of example-robot-data (16 DoF, fingertip spheres r = 12 mm).

    Its fingertip links point along +z; flexion moves them towards +x, the pad side. The contact
    region is the SAH's, a plausible default for a spherical fingertip. The thumb's first link
    overlaps the palm by design, so that pair is not checked.
    """
    share = Path(str(metadata.distribution("example-robot-data").locate_file("cmeel.prefix/share")))
    urdf = share / "example-robot-data/robots/allegro_hand_description/urdf/allegro_right_hand.urdf"
    tips = {"thumb": "link_15.0_tip", "index": "link_3.0_tip"}
    tips.update({"middle": "link_7.0_tip", "ring": "link_11.0_tip"})
    return HandDescription(
        name="allegro",
        urdf_path=urdf,
        fingers=tuple(FingerSpec(n, t, (0.0, 0.0, 1.0), (1.0, 0.0, 0.0)) for n, t in tips.items()),
        fingertip_radius_m=0.012,
        contact_pitch_limits_rad=(-15 * _DEG, 80 * _DEG),
        contact_yaw_limits_rad=(-35 * _DEG, 35 * _DEG),
        excluded_collisions=(("palm_link", "link_13.0"),),
        package_dirs=(share,),
    )


@dataclass(frozen=True)
class ContactState:
    """Fingertip contact kinematics at one configuration, all in ``world``, rows per finger.

    Attributes:
        points: Contact points on the fingertip spheres [m], shape (F, 3).
        centres: Fingertip-sphere centres [m], shape (F, 3).
        normals: Outward unit normals of the fingertips at the contact points, shape (F, 3).
    """

    points: NDArray[np.float64]
    centres: NDArray[np.float64]
    normals: NDArray[np.float64]


@dataclass(frozen=True)
class ContactJacobians:
    """Jacobians of :class:`ContactState` w.r.t. the independent velocity coordinates ``v``.

    The wrist part of ``v`` is the palm twist in the palm frame (Pinocchio's free-flyer
    convention); integrate steps with ``Hand.integrate``. Shapes (F, 3, nv).

    Attributes:
        state: The contact state the Jacobians were computed at.
        points: Jacobians of the contact points [m/rad].
        centres: Jacobians of the fingertip-sphere centres [m/rad].
        angular: Angular-velocity Jacobians of the contact frames (world axes) [1].
    """

    state: ContactState
    points: NDArray[np.float64]
    centres: NDArray[np.float64]
    angular: NDArray[np.float64]

    @cached_property
    def normals(self) -> NDArray[np.float64]:
        """Jacobians of the outward normals: dn = omega x n = -[n]x omega [1/rad]."""
        return -_skew_batch(self.state.normals) @ self.angular


class Hand:
    """A hand: Pinocchio model/data, coal self-collision, and the contact queries of the papers.

    Build it with :func:`load_hand`. ``q`` is Pinocchio's configuration vector (wrist position,
    wrist quaternion ``[x, y, z, w]``, then one angle per independent joint in model order,
    virtual contact joints included) and ``v`` the matching velocity/step vector.
    """

    def __init__(self, description: HandDescription) -> None:
        self.description = description
        model, geometry = _build_models(description)
        self.fingers = description.finger_names
        self.radius_m = description.fingertip_radius_m
        self._tip_frames = [_frame_id(model, f.tip_link) for f in description.fingers]
        self._contact_frames: list[int] = []
        for spec, tip in zip(description.fingers, self._tip_frames, strict=True):
            self._contact_frames.append(self._add_contact_joints(model, spec, tip))
        self._jacobian_frames = self._contact_frames + self._tip_frames
        self._centre_selector = np.array([-self.radius_m, 0.0, 0.0, 1.0])
        self.model = model
        self.data = model.createData()
        self.collision = SelfCollision(model, geometry, description.excluded_collisions)
        self._check_revolute()

    # ----- construction -------------------------------------------------------------------------
    def _add_contact_joints(self, model: pin.Model, spec: FingerSpec, tip_frame: int) -> int:
        tip = model.frames[tip_frame]
        x = np.asarray(spec.tip_axis)
        y = np.asarray(spec.pad_axis)
        if abs(float(x @ y)) > 1e-9:
            raise HandModelError(
                f"finger {spec.name}: tip_axis {spec.tip_axis} and pad_axis {spec.pad_axis} "
                "must be orthogonal unit vectors"
            )
        # Joint frame x = fingertip axis, y = pad: pitch (about z) turns x towards the pad and
        # yaw (about the pitched y) turns it sideways; x then is the outward contact normal.
        R0 = np.column_stack([x, y, np.cross(x, y)])
        placement = tip.placement * pin.SE3(R0, np.zeros(3))
        d = self.description
        pitch = self._add_revolute(
            model, tip.parentJoint, pin.JointModelRZ(), placement,
            f"{spec.name}_contact_pitch", d.contact_pitch_limits_rad,
        )  # fmt: skip
        yaw = self._add_revolute(
            model, pitch, pin.JointModelRY(), pin.SE3.Identity(),
            f"{spec.name}_contact_yaw", d.contact_yaw_limits_rad,
        )  # fmt: skip
        contact = pin.SE3(np.eye(3), np.array([self.radius_m, 0.0, 0.0]))
        frame = pin.Frame(f"{spec.name}_contact", yaw, contact, pin.FrameType.OP_FRAME)
        return int(model.addFrame(frame, False))

    @staticmethod
    def _add_revolute(
        model: pin.Model,
        parent: int,
        joint: pin.JointModel,
        placement: pin.SE3,
        name: str,
        limits: tuple[float, float],
    ) -> int:
        one = np.ones(1)
        lo, hi = np.array([limits[0]]), np.array([limits[1]])
        return int(model.addJoint(parent, joint, placement, name, one, one, lo, hi))

    def _check_revolute(self) -> None:
        for jid in range(2, self.model.njoints):
            j = self.model.joints[jid]
            if j.nq != j.nv or j.nq > 1:
                raise HandModelError(
                    f"joint {self.model.names[jid]} of {self.description.urdf_path} is "
                    f"{j.shortname()}; sahgrasp models hands of revolute/prismatic joints"
                )

    # ----- sizes and names ----------------------------------------------------------------------
    @property
    def nq(self) -> int:
        """Size of ``q``."""
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        """Size of ``v``: 6 wrist + independent finger joints + 2 per finger."""
        return int(self.model.nv)

    @cached_property
    def joint_names(self) -> tuple[str, ...]:
        """Independent hand joints (not wrist, not mimic, not virtual), in model order."""
        return tuple(
            self.model.names[j]
            for j in self._coordinate_joints
            if not self.model.names[j].endswith(("_contact_pitch", "_contact_yaw"))
        )

    @cached_property
    def virtual_joint_names(self) -> tuple[str, ...]:
        """Virtual contact joints, ``(<f>_contact_pitch, <f>_contact_yaw)`` per finger."""
        return tuple(n for f in self.fingers for n in (f"{f}_contact_pitch", f"{f}_contact_yaw"))

    @cached_property
    def mimic_joints(self) -> dict[str, tuple[str, float, float]]:
        """Mimic joint name -> (leader joint name, multiplier, offset)."""
        out = {}
        for jid in range(1, self.model.njoints):
            j = self.model.joints[jid]
            if j.shortname() == "JointModelMimic":
                j = j.extract()
                leader = self._joint_by_q_index(j.idx_q)
                out[str(self.model.names[jid])] = (leader, float(j.scaling), float(j.offset))
        return out

    @cached_property
    def _coordinate_joints(self) -> tuple[int, ...]:
        return tuple(
            jid
            for jid in range(2, self.model.njoints)
            if self.model.joints[jid].shortname() != "JointModelMimic"
        )

    def _joint_by_q_index(self, idx_q: int) -> str:
        for jid in self._coordinate_joints:
            if self.model.joints[jid].idx_q == idx_q:
                return str(self.model.names[jid])
        raise HandModelError(f"no joint has configuration index {idx_q}")

    @cached_property
    def coordinate_names(self) -> tuple[str, ...]:
        """Names of the non-wrist coordinates ``q[7:]`` (= ``v[6:]``), in order."""
        order = sorted(self._coordinate_joints, key=lambda j: self.model.joints[j].idx_q)
        return tuple(str(self.model.names[j]) for j in order)

    def coordinate_index(self, name: str) -> int:
        """Index of joint ``name`` in ``q[7:]`` (and ``v[6:]``)."""
        try:
            return self.coordinate_names.index(name)
        except ValueError:
            raise HandModelError(
                f"{name!r} is not a coordinate of hand {self.description.name}; "
                f"valid: {list(self.coordinate_names)}"
            ) from None

    @cached_property
    def finger_coordinates(self) -> dict[str, NDArray[np.intp]]:
        """Finger name -> indices in ``q[7:]`` of the coordinates that move its contact point."""
        out = {}
        for f, frame in zip(self.fingers, self._contact_frames, strict=True):
            support = self.model.supports[self.model.frames[frame].parentJoint]
            names = {self.model.names[j] for j in support}
            out[f] = np.array(
                [i for i, n in enumerate(self.coordinate_names) if n in names], dtype=np.intp
            )
        return out

    # ----- limits and configurations ------------------------------------------------------------
    @cached_property
    def lower(self) -> NDArray[np.float64]:
        """Lower limits of ``q[7:]`` [rad]."""
        return np.array(self.model.lowerPositionLimit[7:], dtype=np.float64)

    @cached_property
    def upper(self) -> NDArray[np.float64]:
        """Upper limits of ``q[7:]`` [rad]."""
        return np.array(self.model.upperPositionLimit[7:], dtype=np.float64)

    def check_q(self, q: ArrayLike) -> NDArray[np.float64]:
        """Return ``q`` as a float array, or raise if its size is wrong or it holds NaN/inf."""
        arr = np.asarray(q, dtype=np.float64)
        if arr.shape != (self.nq,):
            raise InvalidConfigurationError(
                f"configuration of hand {self.description.name} must have {self.nq} values "
                f"(7 wrist xyz+quat, {self.nq - 7} joints: {list(self.coordinate_names)}), "
                f"got shape {arr.shape}"
            )
        if not np.all(np.isfinite(arr)):
            raise InvalidConfigurationError("configuration holds NaN or inf; all must be finite")
        return arr

    def within_limits(self, q: NDArray[np.float64], tol: float = 1e-9) -> bool:
        """True if every joint coordinate is within its limits (mimic joints follow)."""
        joints = q[7:]
        return bool(np.all(joints >= self.lower - tol) and np.all(joints <= self.upper + tol))

    def configuration(
        self,
        T_world_palm: pin.SE3 | None = None,
        coordinates: ArrayLike | Mapping[str, float] | None = None,
    ) -> NDArray[np.float64]:
        """Assemble ``q`` from a wrist pose and joint coordinates.

        Args:
            T_world_palm: Palm pose in ``world`` (identity if None).
            coordinates: ``q[7:]`` as an array, or a mapping from coordinate names (missing ones
                take the middle of their range). Mimic joints cannot be set: they follow.
        """
        q = np.empty(self.nq)
        pose = pin.SE3.Identity() if T_world_palm is None else T_world_palm
        q[:7] = pin.SE3ToXYZQUAT(pose)
        if coordinates is None or isinstance(coordinates, Mapping):
            q[7:] = 0.5 * (self.lower + self.upper)
            for name, value in (coordinates or {}).items():
                q[7 + self.coordinate_index(name)] = float(value)
        else:
            q[7:] = np.asarray(coordinates, dtype=np.float64)
        return self.check_q(q)

    @staticmethod
    def wrist_pose(q: NDArray[np.float64]) -> pin.SE3:
        """Palm pose ``T_world_palm`` encoded in ``q``."""
        return pin.XYZQUATToSE3(q[:7])

    def joint_values(self, q: NDArray[np.float64]) -> dict[str, float]:
        """Every URDF joint angle [rad] by name, mimic joints included (virtual ones excluded)."""
        coords = dict(zip(self.coordinate_names, q[7:].tolist(), strict=True))
        out = {n: coords[n] for n in self.joint_names}
        for mimic, (leader, scale, offset) in self.mimic_joints.items():
            out[mimic] = scale * coords[leader] + offset
        return out

    def contact_parameters(self, q: NDArray[np.float64]) -> dict[str, tuple[float, float]]:
        """Finger -> (pitch, yaw) [rad] of the virtual contact joints."""
        return {
            f: (
                float(q[7 + self.coordinate_index(f"{f}_contact_pitch")]),
                float(q[7 + self.coordinate_index(f"{f}_contact_yaw")]),
            )
            for f in self.fingers
        }

    def integrate(self, q: NDArray[np.float64], v: NDArray[np.float64]) -> NDArray[np.float64]:
        """Return ``q (+) v`` (Pinocchio's integration on the free-flyer's Lie group)."""
        return np.asarray(pin.integrate(self.model, q, v))

    def random_configuration(
        self,
        rng: np.random.Generator,
        T_world_palm: pin.SE3 | None = None,
        collision_free: bool = False,
        max_tries: int = 10_000,
    ) -> NDArray[np.float64]:
        """Draw joint coordinates uniformly within limits (virtual joints in the contact region).

        Args:
            rng: The random generator (the caller owns the seed).
            T_world_palm: Wrist pose; a uniformly random rotation at the origin if None.
            collision_free: Redraw until the hand has no self-collision.
            max_tries: Draws allowed before giving up with :class:`HandModelError`.
        """
        for _ in range(max_tries):
            pose = _random_rotation(rng) if T_world_palm is None else T_world_palm
            q = self.configuration(pose, rng.uniform(self.lower, self.upper))
            if not collision_free or not self.collision.in_collision(q):
                return q
        raise HandModelError(f"no collision-free configuration in {max_tries} random draws")

    # ----- kinematics ---------------------------------------------------------------------------
    def contact_state(self, q: NDArray[np.float64]) -> ContactState:
        """Contact points, sphere centres and normals of all fingers at ``q`` (world frame)."""
        pin.forwardKinematics(self.model, self.data, q)
        H = np.array(
            [
                pin.updateFramePlacement(self.model, self.data, f).homogeneous
                for f in self._contact_frames
            ]
        )
        return self._state(H)

    def _state(self, H: NDArray[np.float64]) -> ContactState:
        # Homogeneous contact placements: x axis = normal, origin = point; r = p - R n.
        return ContactState(H[:, :3, 3], H[:, :3] @ self._centre_selector, H[:, :3, 0])

    def contact_jacobians(self, q: NDArray[np.float64]) -> ContactJacobians:
        """Contact state and its Jacobians w.r.t. ``v`` (see :class:`ContactJacobians`)."""
        model, data = self.model, self.data
        pin.computeJointJacobians(model, data, q)
        J = np.array([pin.getFrameJacobian(model, data, f, _LWA) for f in self._jacobian_frames])
        # updateFramePlacement returns the placement faster than indexing data.oMf.
        H = np.array(
            [pin.updateFramePlacement(model, data, f).homogeneous for f in self._contact_frames]
        )
        F = len(self.fingers)
        return ContactJacobians(self._state(H), J[:F, :3], J[F:, :3], J[:F, 3:])

    def frame_placements(self, q: NDArray[np.float64]) -> dict[str, pin.SE3]:
        """World placement of every body frame (link) at ``q``, by link name."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return {
            f.name: self.data.oMf[i].copy()
            for i, f in enumerate(self.model.frames)
            if f.type == pin.FrameType.BODY
        }

    def contact_placement(self, q: NDArray[np.float64], finger: str) -> pin.SE3:
        """World placement of ``finger``'s contact frame (origin = point, x = outward normal)."""
        pin.forwardKinematics(self.model, self.data, q)
        frame = self._contact_frames[self._finger_index(finger)]
        return pin.updateFramePlacement(self.model, self.data, frame).copy()

    def contact_frame_id(self, finger: str) -> int:
        """Pinocchio frame id of ``finger``'s contact frame (x axis = outward normal)."""
        return self._contact_frames[self._finger_index(finger)]

    def _finger_index(self, finger: str) -> int:
        try:
            return self.fingers.index(finger)
        except ValueError:
            raise HandModelError(
                f"unknown finger {finger!r} for hand {self.description.name}; "
                f"valid: {list(self.fingers)}"
            ) from None

    def in_collision(self, q: NDArray[np.float64]) -> bool:
        """True if the hand collides with itself at ``q``."""
        return self.collision.in_collision(q)

    def min_distance(self, q: NDArray[np.float64]) -> float:
        """Smallest signed distance [m] between checked pairs of hand bodies at ``q``."""
        return self.collision.min_distance(q)

    def dof(self) -> dict[str, int]:
        """Degrees of freedom: wrist, fingers (independent joints), virtual, total."""
        fingers = len(self.joint_names)
        virtual = len(self.virtual_joint_names)
        return {"wrist": 6, "fingers": fingers, "virtual": virtual, "total": 6 + fingers + virtual}


def _skew_batch(v: NDArray[np.float64]) -> NDArray[np.float64]:
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def _random_rotation(rng: np.random.Generator) -> pin.SE3:
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    return pin.XYZQUATToSE3(np.concatenate([np.zeros(3), quat]))


def _frame_id(model: pin.Model, link: str) -> int:
    if not model.existFrame(link):
        links = sorted(f.name for f in model.frames if f.type == pin.FrameType.BODY)
        raise HandModelError(f"tip link {link!r} is not in the URDF; its links are {links}")
    return int(model.getFrameId(link))


def _build_models(description: HandDescription) -> tuple[pin.Model, pin.GeometryModel]:
    urdf = description.urdf_path
    if not urdf.is_file():
        raise HandModelError(f"URDF of hand {description.name!r} not found: {urdf}")
    try:
        model = pin.buildModelFromUrdf(str(urdf), pin.JointModelFreeFlyer(), "wrist", True)
        dirs = [str(p) for p in description.package_dirs]
        geometry = pin.buildGeomFromUrdf(model, str(urdf), pin.GeometryType.COLLISION, None, dirs)
    except (ValueError, RuntimeError, OSError) as exc:
        raise HandModelError(f"URDF {urdf} does not load in Pinocchio: {exc}") from exc
    return model, geometry


def load_hand(hand: str | os.PathLike[str] | HandDescription) -> Hand:
    """Build a :class:`Hand` from a built-in name, a hand-description JSON path, or a description.

    Args:
        hand: ``"sah"``, ``"allegro"``, a path to a description JSON, or a HandDescription.

    Raises:
        HandModelError: Unknown name, missing or malformed description or URDF, missing tip link.
    """
    if isinstance(hand, HandDescription):
        return Hand(hand)
    text = str(hand)
    if text == "sah":
        return Hand(sah_description())
    if text == "allegro":
        return Hand(allegro_description())
    path = Path(text)
    if not path.suffix or not path.exists():
        raise HandModelError(
            f"unknown hand {text!r}: use one of {list(BUILTIN_HANDS)} or the path of a hand "
            "description JSON file"
        )
    return Hand(HandDescription.from_json(path))
