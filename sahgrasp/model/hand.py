"""The hand model: one Pinocchio model for any hand URDF, with virtual fingertip-contact joints.

``load_hand`` builds, from a URDF and a small :class:`HandDescription`:

* a free-flyer root joint ``wrist`` (the palm pose in ``world``, 6 DoF);
* the URDF joints, with ``<mimic>`` joints honoured by Pinocchio (they carry no coordinate of their
  own, so every computation -- kinematics, Jacobians, integration, sampling, limits -- is in the
  independent coordinates);
* two virtual revolute joints per fingertip, ``<finger>_contact_pitch`` (from the fingertip axis
  towards the pad) and ``<finger>_contact_yaw`` (sideways), placing the contact point on the
  fingertip sphere of radius ``R`` (Claret & Suárez's IK paper, Section 2, Fig. 2b); the contact
  frame's x axis is the fingertip's outward normal at the contact point;
* the coal self-collision model of the URDF collision shapes.

For the SAH this is the paper's 27 DoF: 6 wrist + 13 finger + 8 virtual.
"""

from __future__ import annotations

import copy
import errno
import hashlib
import json
import math
import os
import stat
import sys
from collections import OrderedDict
from collections.abc import Callable, Hashable, Mapping
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from importlib import metadata, resources
from pathlib import Path
from typing import Any, ClassVar, TypeVar, cast

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from sahgrasp.collision.hand_self import Penetration, SelfCollision
from sahgrasp.core.errors import (
    HandModelError,
    InvalidConfigurationError,
    InvalidSettingsError,
    InvalidTargetError,
    SahGraspError,
)
from sahgrasp.model.hand_checks import (
    check_name,
    check_urdf,
    native_message,
    native_stderr,
    number,
    numbers,
    read_json,
    shown,
    shown_path,
)
from sahgrasp.model.hands import HANDS, hand_entry

__all__ = [
    "BUILTIN_HANDS",
    "ContactJacobians",
    "ContactState",
    "FingerSpec",
    "Hand",
    "HandCache",
    "HandDescription",
    "HandState",
    "allegro_description",
    "check_made_for",
    "load_hand",
    "sah_description",
]

BUILTIN_HANDS = HANDS.names()
"""Hand names that ``load_hand`` knows without a description file (a live view of the registry
:data:`sahgrasp.model.hands.HANDS`)."""

_T = TypeVar("_T")
_DEG = math.pi / 180.0
_FINITE_WEIGHT = 1e-10
"""Weight of each coordinate in the finiteness test: sum(q_i 1e-10) cannot overflow for finite
q_i (at most 1.8e298 each), nor fall into the slow subnormal range for joint-sized values."""
_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_WRIST_NQ = 7
"""Entries of ``q`` the free-flyer wrist takes (position, then quaternion)."""


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

    _loaded_digest: ClassVar[str | None] = None
    """Set on the copy a :class:`Hand` keeps: the digest of the URDF bytes it was built from."""

    def __post_init__(self) -> None:
        _check_description(self)

    def digest(self) -> str:
        """SHA-256 of the kinematic description (URDF text and this description, not paths).

        The description a :class:`Hand` keeps returns the digest of the URDF bytes the hand was
        built from, computed once, so a file edited on disk afterwards cannot make a loaded hand
        claim another hand's checkpoints. Any other description hashes the file as it is now,
        cached per file path, modification time, size and inode.

        Raises:
            HandModelError: The URDF file cannot be read.
        """
        if self._loaded_digest is not None:
            return self._loaded_digest
        return _finish_digest(_urdf_hash(self.urdf_path).copy(), self._kinematic_json)

    def _loaded_from(self, urdf: bytes) -> HandDescription:
        """A copy whose digest is pinned to ``urdf``, the bytes a hand is built from."""
        loaded = copy.copy(self)
        digest = _finish_digest(hashlib.sha256(urdf), self._kinematic_json)
        object.__setattr__(loaded, "_loaded_digest", digest)
        return loaded

    @cached_property
    def _kinematic_json(self) -> bytes:
        fields = {
            "fingers": [[f.name, f.tip_link, f.tip_axis, f.pad_axis] for f in self.fingers],
            "fingertip_radius_m": self.fingertip_radius_m,
            "contact_pitch_limits_rad": self.contact_pitch_limits_rad,
            "contact_yaw_limits_rad": self.contact_yaw_limits_rad,
        }
        return json.dumps(fields, sort_keys=True).encode()

    @classmethod
    def from_json(cls, path: str | os.PathLike[str]) -> HandDescription:
        """Read a hand description file; its ``urdf`` is relative to the file's folder.

        The file is a UTF-8 JSON object with exactly these keys: ``name``, ``urdf``,
        ``fingertip_radius_m``, ``contact_pitch_limits_rad``, ``contact_yaw_limits_rad``,
        ``fingers`` (a list of ``{"name", "tip_link", "tip_axis", "pad_axis"}``) and optionally
        ``excluded_collisions`` and ``package_dirs``. Axes are normalised.

        Raises:
            HandModelError: Unreadable, not UTF-8 JSON, a key missing or unknown, or a value
                invalid (see ``docs/methods/hand-model.md``).
        """
        path = Path(path)
        data = read_json(path, "hand description")
        where = f"hand description {shown(path)}"
        if not isinstance(data, dict):
            raise HandModelError(f"{where} must hold a JSON object, got {type(data).__name__}")
        missing = [k for k in _REQUIRED_KEYS if k not in data]
        unknown = [k for k in data if k not in _REQUIRED_KEYS + _OPTIONAL_KEYS]
        if missing or unknown:
            raise HandModelError(
                f"{where}: missing keys {missing}, unknown keys {[shown(k) for k in unknown]}; "
                f"it needs {list(_REQUIRED_KEYS)} and may have {list(_OPTIONAL_KEYS)}"
            )
        folder = path.parent
        return cls(
            name=check_name(f"{where}: name", data["name"]),
            urdf_path=folder / check_name(f"{where}: urdf", data["urdf"]),
            fingers=tuple(_finger(f"{where}: fingers", f) for f in _list(where, data, "fingers")),
            fingertip_radius_m=number(f"{where}: fingertip_radius_m", data["fingertip_radius_m"]),
            contact_pitch_limits_rad=_pair(where, data, "contact_pitch_limits_rad"),
            contact_yaw_limits_rad=_pair(where, data, "contact_yaw_limits_rad"),
            excluded_collisions=tuple(
                _link_pair(f"{where}: excluded_collisions", p)
                for p in _list(where, data, "excluded_collisions")
            ),
            package_dirs=tuple(
                folder / check_name(f"{where}: package_dirs", p)
                for p in _list(where, data, "package_dirs")
            ),
        )


_REQUIRED_KEYS = (
    "name",
    "urdf",
    "fingertip_radius_m",
    "contact_pitch_limits_rad",
    "contact_yaw_limits_rad",
    "fingers",
)
_OPTIONAL_KEYS = ("excluded_collisions", "package_dirs")
_FINGER_KEYS = ("name", "tip_link", "tip_axis", "pad_axis")


def _list(where: str, data: Mapping[str, Any], key: str) -> list[Any]:
    value = data.get(key, [])
    if not isinstance(value, list):
        raise HandModelError(f"{where}: {key} must be a list, got {type(value).__name__}")
    return value


def _pair(where: str, data: Mapping[str, Any], key: str) -> tuple[float, float]:
    lo, hi = numbers(f"{where}: {key}", data[key], 2)
    return (lo, hi)


def _link_pair(what: str, value: object) -> tuple[str, str]:
    if not isinstance(value, list) or len(value) != 2:
        raise HandModelError(f"{what}: each entry must be a pair of link names, got {value!r}")
    return (check_name(what, value[0]), check_name(what, value[1]))


def _finger(what: str, value: object) -> FingerSpec:
    if not isinstance(value, dict) or sorted(value) != sorted(_FINGER_KEYS):
        raise HandModelError(
            f"{what}: each finger must be an object with exactly the keys {list(_FINGER_KEYS)}, "
            f"got {shown(value)[:200]}"
        )
    name = check_name(f"{what}: finger name", value["name"])
    return FingerSpec(
        name,
        check_name(f"{what}: {name} tip_link", value["tip_link"]),
        _unit3(f"{what}: {name} tip_axis", value["tip_axis"]),
        _unit3(f"{what}: {name} pad_axis", value["pad_axis"]),
    )


def _unit3(what: str, values: object) -> tuple[float, float, float]:
    x, y, z = numbers(what, values, 3)
    norm = math.sqrt(x * x + y * y + z * z)
    if not 0.0 < norm < math.inf:
        raise HandModelError(f"{what} must be a non-zero finite vector, got {values!r}")
    return (x / norm, y / norm, z / norm)


def _check_description(d: HandDescription) -> None:
    """The rules of ``docs/methods/hand-model.md`` on a description, however it was built."""
    what = f"hand description {d.name!r}"
    check_name("hand description name", d.name)
    if not d.fingers:
        raise HandModelError(f"{what} has no fingers; give at least one")
    for kind in ("name", "tip_link"):
        values = [check_name(f"{what}: finger {kind}", getattr(f, kind)) for f in d.fingers]
        repeated = sorted({v for v in values if values.count(v) > 1})
        if repeated:
            raise HandModelError(f"{what}: finger {kind}s {repeated} appear more than once")
    for f in d.fingers:
        _check_axes(f"{what}: finger {f.name!r}", f)
    radius = number(f"{what}: fingertip_radius_m", d.fingertip_radius_m)
    if not 0.0 < radius <= _MAX_RADIUS_M:
        raise HandModelError(
            f"{what}: fingertip_radius_m must be in (0, {_MAX_RADIUS_M}] m, got {radius}"
        )
    for key in ("contact_pitch_limits_rad", "contact_yaw_limits_rad"):
        lo, hi = numbers(f"{what}: {key}", getattr(d, key), 2)
        if not -math.pi < lo < hi < math.pi:
            raise HandModelError(
                f"{what}: {key} must be [lower, upper] with -pi < lower < upper < pi, "
                f"got [{lo}, {hi}]"
            )
    for a, b in d.excluded_collisions:
        check_name(f"{what}: excluded_collisions link", a)
        check_name(f"{what}: excluded_collisions link", b)


_MAX_RADIUS_M = 1.0
"""Largest fingertip radius [m]: a larger one is a unit mistake (mm given as m)."""


def _check_axes(what: str, finger: FingerSpec) -> None:
    axes = []
    for name in ("tip_axis", "pad_axis"):
        vec = np.array(numbers(f"{what} {name}", getattr(finger, name), 3))
        if abs(float(vec @ vec) - 1.0) > _AXIS_TOL:
            raise HandModelError(f"{what}: {name} must be a unit vector, got {tuple(vec)}")
        axes.append(vec)
    if abs(float(axes[0] @ axes[1])) > _AXIS_TOL:
        raise HandModelError(
            f"{what}: tip_axis {finger.tip_axis} and pad_axis {finger.pad_axis} must be "
            "orthogonal unit vectors"
        )


_AXIS_TOL = 1e-9
"""Tolerance on unit length and orthogonality of the fingertip axes (they become rotation
columns, so a larger error would distort the contact frames)."""


@lru_cache(maxsize=16)
def _urdf_file_hash(path: str, stamp: tuple[int, int, int]) -> hashlib._Hash:
    del stamp  # part of the cache key only: a changed file is hashed again
    return hashlib.sha256(Path(path).read_bytes())


def _urdf_hash(path: Path) -> hashlib._Hash:
    try:
        st = path.stat()
        return _urdf_file_hash(str(path), (st.st_mtime_ns, st.st_size, st.st_ino))
    except OSError as exc:
        raise HandModelError(f"cannot read URDF {shown(path)}: {exc.strerror}") from exc


def _finish_digest(urdf_hash: hashlib._Hash, kinematic_json: bytes) -> str:
    urdf_hash.update(kinematic_json)
    return urdf_hash.hexdigest()


def sah_description() -> HandDescription:
    """The right Schunk Anthropomorphic Hand (``urdf/sah_right.urdf``, from its public fact sheet).

    The fingertip sphere has radius 10 mm, centred 29.5 mm along the distal phalanx, as in the
    IK model of the paper's lab; the accepted contact region is -15..80 deg towards the pad and
    -35..35 deg sideways (Claret & Suárez's IK paper, Fig. 2b).
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


@dataclass(frozen=True)
class HandState:
    """Immutable kinematic snapshot of a hand at one configuration (every array is read-only).

    Unlike Pinocchio's shared ``hand.data``, a snapshot cannot be overwritten by a later query,
    so it can be kept, compared and passed between modules without call-order dependencies.

    Attributes:
        q: The configuration (a read-only copy).
        contacts: Contact points, sphere centres and normals (world frame).
        jacobians: Their Jacobians w.r.t. ``v``; None when not requested.
        world_jacobian: Pinocchio's stack of every joint's motion subspace in the world frame,
            shape (6, nvExtended) (linear part first, about the world origin; one column per
            joint, mimic joints included); None without Jacobians.
    """

    q: NDArray[np.float64]
    contacts: ContactState
    jacobians: ContactJacobians | None
    world_jacobian: NDArray[np.float64] | None
    _supports: NDArray[np.float64] = field(repr=False)
    _reduce: NDArray[np.float64] = field(repr=False)

    def point_jacobian(self, joint: int, point: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian (3, nv) [m/rad] of a world point ``point`` [m] fixed to ``joint``'s body.

        Joint 0 is the world: its Jacobian is zero.

        Raises:
            InvalidConfigurationError: The snapshot was taken without Jacobians.
        """
        if self.world_jacobian is None:
            raise InvalidConfigurationError(
                "this hand state has no Jacobians; take it with hand.state(q, jacobians=True)"
            )
        J = self.world_jacobian
        return _point_jacobians(J, self._supports, self._reduce, [joint], point[None])[0]


@dataclass(frozen=True)
class _Layout:
    """Constant matrices that turn the joint vector into rows of contact quantities.

    Attributes:
        select: (3 k, 12 n) from :meth:`Hand._joint_vector` (``n`` joint placements) to the
            ``k`` blocks' values (points, centres [m] or normals).
        lever: (3 k, 18 k) from the blocks' values to the ``-[x]x`` entries of each block's
            ``[I, -[x]x]`` (zero for a normal block).
        base: (18 k,) the constant entries of those 3 x 6 blocks (``[I, 0]`` or ``[0, I]``).
        mask: (3 k, nvExtended or nv) 1 on the columns that move each block's body (those of
            ``v`` when the hand folds the mimic columns first).
    """

    select: NDArray[np.float64]
    lever: NDArray[np.float64]
    base: NDArray[np.float64]
    mask: NDArray[np.float64]


class HandCache:
    """Values derived from one hand model, built on first use and kept while the hand lives.

    Each :class:`Hand` owns one (``hand.cache``): the compiled kinematic tree, the default IK
    sequence and grasp database, the samplers' reach. Owned by the hand, they are freed with it
    and never shared between two hand objects, so no module-level table keeps a hand alive.
    """

    __slots__ = ("_values",)

    def __init__(self) -> None:
        self._values: dict[str, Any] = {}

    def get(self, key: str, build: Callable[[], _T]) -> _T:
        """The value kept as ``key``, built by ``build()`` on the first request."""
        if key not in self._values:
            self._values[key] = build()
        return cast(_T, self._values[key])

    def kept(self, kind: str, key: Hashable, build: Callable[[], _T], size: int) -> _T:
        """The value of ``kind`` for ``key``, built on first request; ``size`` kept per kind.

        For values derived from the hand and another input (an object): the ``size`` most
        recently requested are kept, the least recently requested is dropped first.
        """
        kept: OrderedDict[Hashable, Any] = self.get(kind, OrderedDict)
        if key in kept:
            kept.move_to_end(key)
            return cast(_T, kept[key])
        value = kept[key] = build()
        while len(kept) > size:
            kept.popitem(last=False)
        return value

    def __contains__(self, key: object) -> bool:
        return key in self._values

    def clear(self) -> None:
        """Forget every value (they are rebuilt on the next request)."""
        self._values.clear()


class Hand:
    """A hand: Pinocchio model/data, coal self-collision, and the contact queries of the papers.

    Build it with :func:`load_hand`. ``q`` is Pinocchio's configuration vector (wrist position,
    wrist quaternion ``[x, y, z, w]``, then one angle per independent joint in model order,
    virtual contact joints included) and ``v`` the matching velocity/step vector.
    """

    def __init__(self, description: HandDescription) -> None:
        urdf = _read_urdf(description)
        self.description = description._loaded_from(urdf)
        self.cache = HandCache()
        model, geometry = _build_models(description, check_urdf(urdf, shown(description.urdf_path)))
        self.fingers = description.finger_names
        self.radius_m = description.fingertip_radius_m
        self._tip_frames = [_frame_id(model, f.tip_link) for f in description.fingers]
        self._contact_frames: list[int] = []
        for spec, tip in zip(description.fingers, self._tip_frames, strict=True):
            self._contact_frames.append(self._add_contact_joints(model, spec, tip))
        self.model = model
        self.data = model.createData()  # never replaced: the views below point into it
        self._q_shape = (model.nq,)
        self._finite_weights = np.full(model.nq, _FINITE_WEIGHT)
        self._supports, self._reduce = _support_masks(model)
        # The contact frame of each finger hangs on its yaw joint, whose origin is the
        # fingertip-sphere centre and whose x axis is the outward normal (_add_contact_joints).
        self._yaw_joints = [int(model.frames[f].parentJoint) for f in self._contact_frames]
        # Views into data.oMi and data.J, which Pinocchio writes in place: the world placements
        # of the yaw joints are read after a kinematics pass without a call per frame.
        self._first_yaw = min(self._yaw_joints)
        self._placement_parts, self._placements = _placement_views(
            self.data, range(self._first_yaw, max(self._yaw_joints) + 1)
        )
        self._world_jacobian = self.data.J
        # Folding the mimic columns before masking (6 rows instead of one per Jacobian row)
        # gives the same rows when every mimic joint moves the same contacts as its leader.
        # Per finger: its mask on the columns of data.J, or on those of v when folding first.
        self._finger_masks = self._supports[self._yaw_joints]
        folds = (self._reduce != 0).astype(np.float64)  # ext column -> the v column it joins
        hits = self._finger_masks.dot(folds)  # per finger and v column: moving ext columns
        self._fold_first = bool(np.all((hits == 0) | (hits == folds.sum(axis=0))))
        if self._fold_first:
            self._finger_masks = (hits > 0).astype(np.float64)
        F = len(self.fingers)
        self._state_layout = self._layout(
            [(kind, i) for kind in ("point", "centre", "normal") for i in range(F)]
        )
        self._stack_layouts: dict[tuple[int, ...], _Layout] = {}
        self._all_fingers = self._stack_layout(list(range(F)))
        self._check_excluded(description.excluded_collisions)
        self.collision = SelfCollision(model, geometry, description.excluded_collisions)

    # ----- construction -------------------------------------------------------------------------
    def _add_contact_joints(self, model: pin.Model, spec: FingerSpec, tip_frame: int) -> int:
        tip = model.frames[tip_frame]
        x = np.asarray(spec.tip_axis)
        y = np.asarray(spec.pad_axis)
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
        if model.existJointName(name):
            raise HandModelError(
                f"the URDF has a joint named {name!r}, the name of a virtual contact joint "
                "sahgrasp adds; rename that joint or the finger"
            )
        one = np.ones(1)
        lo, hi = np.array([limits[0]]), np.array([limits[1]])
        return int(model.addJoint(parent, joint, placement, name, one, one, lo, hi))

    def _check_excluded(self, pairs: tuple[tuple[str, str], ...]) -> None:
        links = {f.name for f in self.model.frames if f.type == pin.FrameType.BODY}
        unknown = sorted({name for pair in pairs for name in pair} - links)
        if unknown:
            raise HandModelError(
                f"excluded_collisions of hand {self.description.name!r} name {unknown}, which "
                f"are not links of its URDF; its links are {sorted(links)}"
            )

    # ----- sizes and names ----------------------------------------------------------------------
    @cached_property
    def nq(self) -> int:
        """Size of ``q``."""
        return int(self.model.nq)

    @cached_property  # read in every IK iteration: a plain attribute after the first read
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
        return np.array(self.model.lowerPositionLimit[_WRIST_NQ:], dtype=np.float64)

    @cached_property
    def upper(self) -> NDArray[np.float64]:
        """Upper limits of ``q[7:]`` [rad]."""
        return np.array(self.model.upperPositionLimit[_WRIST_NQ:], dtype=np.float64)

    @cached_property
    def bound_tests(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(lower + 1e-12, upper - 1e-12)`` [rad]: a coordinate beyond one sits at its bound.

        The active-set tests of the IK compare with these every iteration.
        """
        return self.lower + 1e-12, self.upper - 1e-12

    def check_q(self, q: ArrayLike) -> NDArray[np.float64]:
        """Return ``q`` as a float array, or raise if its size is wrong or it holds NaN/inf.

        Raises:
            InvalidConfigurationError: ``q`` is not numbers, has the wrong size or holds NaN/inf.
        """
        arr = _float_array("configuration", q)
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
        """True if every joint coordinate is within its limits (mimic joints follow).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        joints = self.finger_part(self._finite(q))
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

        Raises:
            InvalidConfigurationError: ``T_world_palm`` is not a ``pinocchio.SE3``, or the
                coordinates have the wrong size or hold NaN/inf.
            HandModelError: A coordinate name is not the hand's.
        """
        q = np.empty(self.nq)
        pose = _pose("T_world_palm", T_world_palm)
        self.wrist_part(q)[:] = pin.SE3ToXYZQUAT(pose)
        if coordinates is None or isinstance(coordinates, Mapping):
            self.finger_part(q)[:] = 0.5 * (self.lower + self.upper)
            for name, value in (coordinates or {}).items():
                q[7 + self.coordinate_index(name)] = float(value)
        else:
            joints = _float_array("coordinates", coordinates)
            if joints.shape != (self.nq - _WRIST_NQ,):
                raise InvalidConfigurationError(
                    f"coordinates of hand {self.description.name} must be {self.nq - _WRIST_NQ} "
                    f"values {list(self.coordinate_names)} or a mapping of them, got shape "
                    f"{joints.shape}"
                )
            self.finger_part(q)[:] = joints
        return self.check_q(q)

    @staticmethod
    def wrist_part(q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The wrist part of ``q``: position [m] and quaternion ``[x, y, z, w]`` (a view, 7)."""
        return q[:_WRIST_NQ]

    @staticmethod
    def finger_part(q: NDArray[np.float64]) -> NDArray[np.float64]:
        """The joint coordinates of ``q`` [rad], virtual contact joints included (a view)."""
        return q[_WRIST_NQ:]

    @staticmethod
    def wrist_pose(q: NDArray[np.float64]) -> pin.SE3:
        """Palm pose ``T_world_palm`` encoded in ``q``."""
        return pin.XYZQUATToSE3(q[:_WRIST_NQ])

    def joint_values(self, q: NDArray[np.float64]) -> dict[str, float]:
        """Every URDF joint angle [rad] by name, mimic joints included (virtual ones excluded).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        q = self._finite(q)
        coords = dict(zip(self.coordinate_names, self.finger_part(q).tolist(), strict=True))
        out = {n: coords[n] for n in self.joint_names}
        for mimic, (leader, scale, offset) in self.mimic_joints.items():
            out[mimic] = scale * coords[leader] + offset
        return out

    def contact_parameters(self, q: NDArray[np.float64]) -> dict[str, tuple[float, float]]:
        """Finger -> (pitch, yaw) [rad] of the virtual contact joints.

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        q = self._finite(q)
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
            rng: The random generator (the caller owns the seed), e.g.
                ``np.random.default_rng(seed)``.
            T_world_palm: Wrist pose; a uniformly random rotation at the origin if None.
            collision_free: Redraw until the hand has no self-collision.
            max_tries: Draws allowed (>= 1) before giving up with :class:`HandModelError`.

        Raises:
            InvalidSettingsError: ``rng`` is not a ``numpy.random.Generator``, or ``max_tries``
                is not an integer >= 1.
            InvalidConfigurationError: ``T_world_palm`` is not a ``pinocchio.SE3``.
            HandModelError: No collision-free configuration in ``max_tries`` draws.
        """
        if not isinstance(rng, np.random.Generator):
            raise InvalidSettingsError(
                "rng must be a numpy.random.Generator (np.random.default_rng(seed)), got "
                f"{type(rng).__name__}"
            )
        if isinstance(max_tries, bool) or not isinstance(max_tries, int) or max_tries < 1:
            raise InvalidSettingsError(f"max_tries must be an integer >= 1, got {max_tries!r}")
        _pose("T_world_palm", T_world_palm)
        for _ in range(max_tries):
            pose = _random_rotation(rng) if T_world_palm is None else T_world_palm
            q = self.configuration(pose, rng.uniform(self.lower, self.upper))
            if not collision_free or not self.collision.in_collision(q):
                return q
        raise HandModelError(f"no collision-free configuration in {max_tries} random draws")

    # ----- kinematics ---------------------------------------------------------------------------
    def contact_state(self, q: NDArray[np.float64]) -> ContactState:
        """Contact points, sphere centres and normals of all fingers at ``q`` (world frame).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        pin.forwardKinematics(self.model, self.data, self._finite(q))
        return _contact_state(self._state_layout.select.dot(self._joint_vector()))

    def _joint_vector(self) -> NDArray[np.float64]:
        """The world placements of the joints from the first to the last yaw joint, flat.

        Per joint its rotation (column-major) then its translation, 12 values. A view of
        ``data.oMi`` itself when Pinocchio stores them contiguously (no copy), else a
        concatenation of per-joint views (:func:`_flattened`).
        """
        if self._placements is not None:
            return self._placements
        return _flattened(self._placement_parts)

    def contact_stack(
        self, q: NDArray[np.float64], fingers: list[int] | None = None
    ) -> NDArray[np.float64]:
        """Contact points and sphere centres as one vector ``(p_i, r_i)`` per finger [m].

        The solvers' hot path: one forward-kinematics pass and one product, shape (6 k,) for the
        ``k`` fingers (indices into :attr:`fingers`; all if None).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        pin.forwardKinematics(self.model, self.data, self._finite(q))
        layout = self._all_fingers if fingers is None else self._stack_layout(fingers)
        return np.asarray(layout.select.dot(self._joint_vector()))

    def contact_stack_jacobian(
        self, q: NDArray[np.float64], fingers: list[int] | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`contact_stack` and its Jacobian w.r.t. ``v``, shape (6 k, nv) [m/rad].

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        pin.computeJointJacobians(self.model, self.data, self._finite(q))
        layout = self._all_fingers if fingers is None else self._stack_layout(fingers)
        stack = np.asarray(layout.select.dot(self._joint_vector()))
        return stack, self._rows_jacobian(layout, stack)

    def _rows_jacobian(self, layout: _Layout, values: NDArray[np.float64]) -> NDArray[np.float64]:
        """Jacobian (rows, nv) of ``layout``'s ``values`` from ``data.J`` (joint Jacobians set).

        Each 3-row block is ``[I, -[x]x] J_w`` for a point ``x`` fixed to the finger's contact
        body, or ``[0, I] J_w`` for its angular velocity, on the columns that move that body,
        mimic columns folded into their leaders: a few products on constant matrices (one
        Python-to-C crossing each) instead of a Pinocchio call per frame. The fold goes first
        (on the 6 rows of ``data.J``) when every mimic joint moves the same fingers as its
        leader, the case of the built-in hands; otherwise after the mask.
        """
        blocks = (layout.base + values.dot(layout.lever)).reshape(-1, 6)
        if self._fold_first:
            J = blocks.dot(self._world_jacobian.dot(self._reduce))
            J *= layout.mask
            return J
        J = blocks.dot(self._world_jacobian)
        J *= layout.mask
        return np.asarray(J.dot(self._reduce))

    def _stack_layout(self, fingers: list[int]) -> _Layout:
        """The layout of :meth:`contact_stack`, ``(p_i, r_i)`` per finger of ``fingers``.

        Raises:
            InvalidTargetError: ``fingers`` is not a non-empty list of distinct finger indices.
        """
        try:
            key = tuple(fingers)
            layout = self._stack_layouts.get(key)
        except TypeError:  # not iterable, or unhashable items
            key, layout = (), None
        if layout is None:
            self._check_finger_indices(fingers, key)
            rows = [(kind, i) for i in key for kind in ("point", "centre")]
            layout = self._stack_layouts[key] = self._layout(rows)
        return layout

    def _check_finger_indices(self, fingers: object, key: tuple[object, ...]) -> None:
        """Refuse what :meth:`_stack_layout` cannot serve (checked once per new selection)."""
        count = len(self.fingers)
        valid = (
            len(key) > 0
            and all(isinstance(i, int | np.integer) and not isinstance(i, bool) for i in key)
            and all(0 <= int(i) < count for i in key)  # type: ignore[call-overload]
            and len(set(key)) == len(key)
        )
        if not valid:
            raise InvalidTargetError(
                f"fingers must be distinct indices 0..{count - 1} into {list(self.fingers)} "
                f"(None: all), got {fingers!r}"
            )

    def _layout(self, blocks: list[tuple[str, int]]) -> _Layout:
        """Constant matrices of a list of (``point``/``centre``/``normal``, finger) 3-row blocks.

        In :meth:`_joint_vector`, finger ``i``'s yaw joint holds the outward normal ``n_i`` as
        the first rotation column and the sphere centre ``c_i`` as the translation; the contact
        point is ``p_i = c_i + R n_i``. A normal block's Jacobian is the contact frame's
        angular velocity (:attr:`ContactJacobians.angular`).
        """
        k = len(blocks)
        select = np.zeros((3 * k, _SE3_SIZE * (max(self._yaw_joints) - self._first_yaw + 1)))
        base = np.zeros((k, 3, 6))
        skew = np.zeros((3 * k, k, 3, 6))  # a block's point -> its -[x]x entries
        eye = np.eye(3)
        for b, (kind, i) in enumerate(blocks):
            rows, normal = (
                slice(3 * b, 3 * b + 3),
                _SE3_SIZE * (self._yaw_joints[i] - self._first_yaw),
            )
            centre = normal + 9
            if kind == "normal":
                select[rows, normal : normal + 3] = eye
                base[b, :, 3:] = eye
                continue
            select[rows, centre : centre + 3] = eye
            select[rows, normal : normal + 3] = self.radius_m * eye if kind == "point" else 0.0
            base[b, :, :3] = eye
            for a in range(3):
                skew[3 * b + a, b, :, 3:] = -_SKEW_BASIS[a].reshape(3, 3)
        fingers = [i for _, i in blocks]
        return _Layout(
            select=select,
            lever=skew.reshape(3 * k, -1),
            base=base.ravel(),
            mask=np.repeat(self._finger_masks[fingers], 3, axis=0),
        )

    def state(self, q: NDArray[np.float64], jacobians: bool = False) -> HandState:
        """Immutable snapshot of the hand at ``q`` (see :class:`HandState`).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        q = np.array(self._finite(q))
        if not jacobians:
            state = self.contact_state(q)
            return _frozen(HandState(q, state, None, None, self._supports, self._reduce))
        jac = self._jacobians(q)
        J = np.array(self.data.J)
        return _frozen(HandState(q, jac.state, jac, J, self._supports, self._reduce))

    def contact_jacobians(self, q: NDArray[np.float64]) -> ContactJacobians:
        """Contact state and its Jacobians w.r.t. ``v`` (see :class:`ContactJacobians`).

        Leaves the joint Jacobians and placements of ``q`` in ``data`` (``data.J``, ``oMi``).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        return self._jacobians(self._finite(q))

    def _jacobians(self, q: NDArray[np.float64]) -> ContactJacobians:
        pin.computeJointJacobians(self.model, self.data, q)
        values = self._state_layout.select.dot(self._joint_vector())
        J = self._rows_jacobian(self._state_layout, values).reshape(3, len(self.fingers), 3, -1)
        return ContactJacobians(_contact_state(values), J[0], J[1], J[2])

    def frame_placements(self, q: NDArray[np.float64]) -> dict[str, pin.SE3]:
        """World placement of every body frame (link) at ``q``, by link name.

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        pin.framesForwardKinematics(self.model, self.data, self._finite(q))
        return {
            f.name: self.data.oMf[i].copy()
            for i, f in enumerate(self.model.frames)
            if f.type == pin.FrameType.BODY
        }

    def contact_placement(self, q: NDArray[np.float64], finger: str) -> pin.SE3:
        """World placement of ``finger``'s contact frame (origin = point, x = outward normal)."""
        pin.forwardKinematics(self.model, self.data, self._finite(q))
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
        """True if the hand collides with itself at ``q``.

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        return self.collision.in_collision(self._finite(q))

    def penetrations(
        self, q: NDArray[np.float64], margin_m: float, pairs: NDArray[np.intp] | None = None
    ) -> list[Penetration]:
        """Pairs of hand bodies closer than ``margin_m`` [m] at ``q``, with their witnesses.

        ``pairs``: indices into ``collision.pairs`` of the only pairs to query (None: all).

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        return self.collision.penetrations(self._finite(q), margin_m, pairs)

    def min_distance(self, q: NDArray[np.float64]) -> float:
        """Smallest signed distance [m] between checked pairs of hand bodies at ``q``.

        Raises:
            InvalidConfigurationError: ``q`` has the wrong size or holds NaN/inf.
        """
        return self.collision.min_distance(self._finite(q))

    def _finite(self, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``q`` if it is a finite configuration of the right size, else :meth:`check_q`'s error.

        The hot-path test is one dot product (about 0.6 us): NaN or inf make it non-finite, and
        the weights of :data:`_FINITE_WEIGHT` keep it from overflowing for any finite ``q``.
        """
        try:
            if q.shape == self._q_shape and math.isfinite(q.dot(self._finite_weights)):
                return q
        except (AttributeError, TypeError, ValueError):
            pass
        return self.check_q(q)

    def dof(self) -> dict[str, int]:
        """Degrees of freedom: wrist, fingers (independent joints), virtual, total."""
        fingers = len(self.joint_names)
        virtual = len(self.virtual_joint_names)
        return {"wrist": 6, "fingers": fingers, "virtual": virtual, "total": 6 + fingers + virtual}


_SKEW_BASIS = np.array(
    [
        [0, 0, 0, 0, 0, -1, 0, 1, 0],
        [0, 0, 1, 0, 0, 0, -1, 0, 0],
        [0, -1, 0, 1, 0, 0, 0, 0, 0],
    ],
    dtype=np.float64,
)
"""``p @ _SKEW_BASIS`` is the flattened cross-product matrix ``[p]x`` of the row vector ``p``."""


def _point_jacobians(
    world_jacobian: NDArray[np.float64],
    supports: NDArray[np.float64],
    reduce: NDArray[np.float64],
    joints: list[int],
    points: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Jacobians (m, 3, nv) [m/rad] of world points ``points`` (m, 3) fixed to ``joints``' bodies.

    ``v_p = v_o + omega x p = J_lin - [p]x J_ang`` on the columns of the joints that move the
    body (``supports``), mimic columns folded into their leaders (``reduce``): all points in a
    few batched products (joint 0, the world, has no supporting column: a zero Jacobian).
    """
    skews = (points @ _SKEW_BASIS).reshape(-1, 3, 3)
    moving = (world_jacobian[:3] - skews @ world_jacobian[3:]) * supports[joints][:, None, :]
    return np.asarray(moving @ reduce)


_SE3_SIZE = 12
"""Doubles in Pinocchio's SE3: the rotation (column-major 3 x 3), then the translation."""


def _placement_views(
    data: pin.Data, joints: range
) -> tuple[list[NDArray[np.float64]], NDArray[np.float64] | None]:
    """Views of the world placements of ``joints`` in ``data.oMi``, and one flat view of them all.

    The parts are each joint's rotation (3 x 3) and translation (3,), views that Pinocchio's
    in-place writes update. The flat view, :func:`_flattened` of the parts without a copy,
    exists when they lie back to back in memory, rotations column-major (checked address by
    address: Pinocchio's ``std::vector<SE3>`` of 96-byte elements); else it is None. Both stay
    valid while ``data`` lives: Pinocchio never reallocates ``oMi``.
    """
    parts = [part for j in joints for part in (data.oMi[j].rotation, data.oMi[j].translation)]
    start = parts[0].__array_interface__["data"][0]
    offset, adjacent = 0, True
    for part in parts:
        adjacent &= part.__array_interface__["data"][0] == start + offset * part.itemsize
        adjacent &= part.flags.f_contiguous and part.itemsize == parts[0].itemsize
        offset += part.size
    if not adjacent:
        return parts, None
    whole = np.lib.stride_tricks.as_strided(
        parts[0], shape=(offset,), strides=(parts[0].itemsize,), writeable=False
    )
    return parts, whole


def _flattened(parts: list[NDArray[np.float64]]) -> NDArray[np.float64]:
    """The parts of :func:`_placement_views` flat, rotations column-major (a new array)."""
    return np.concatenate([part.ravel(order="F") for part in parts])


def _contact_state(values: NDArray[np.float64]) -> ContactState:
    """The contact state from the values (points, centres, normals; (9 F,)) of its layout."""
    # Indexing, not tuple unpacking: iterating over an array measured about 1 us slower.
    rows = values.reshape(3, -1, 3)
    return ContactState(rows[0], rows[1], rows[2])


def _support_masks(model: pin.Model) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Masks of the columns of ``data.J`` that move each joint's body, and ``data.J`` -> ``v``.

    Pinocchio's ``data.J`` has one column per joint degree of freedom, mimic joints included
    (``nvExtended`` columns); ``v`` has only the independent ones. Returns the masks, shape
    (njoints, nvExtended), 1 where the column moves the joint's body, and the matrix
    (nvExtended, nv) folding a mimic joint's column into its leader's, times the multiplier.
    """
    masks = np.zeros((model.njoints, model.nvExtended))
    reduce = np.zeros((model.nvExtended, model.nv))
    for j in range(1, model.njoints):
        joint = model.joints[j]
        ext, width = joint.idx_vExtended, max(joint.nv, 1)
        scale = joint.extract().scaling if joint.shortname() == "JointModelMimic" else 1.0
        reduce[ext : ext + width, joint.idx_v : joint.idx_v + width] += scale * np.eye(width)
        for k in model.supports[j][1:]:
            first = model.joints[k].idx_vExtended
            masks[j, first : first + max(model.joints[k].nv, 1)] = 1.0
    return masks, reduce


def _frozen(state: HandState) -> HandState:
    """``state`` with every array made read-only (a snapshot cannot be changed in place)."""
    arrays = [state.q, *vars(state.contacts).values(), state.world_jacobian]
    if state.jacobians is not None:
        arrays += [state.jacobians.points, state.jacobians.centres, state.jacobians.angular]
    for array in arrays:
        if array is not None:
            array.flags.writeable = False
    return state


def _skew_batch(v: NDArray[np.float64]) -> NDArray[np.float64]:
    S = np.zeros((len(v), 3, 3))
    S[:, 0, 1], S[:, 0, 2], S[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    S[:, 1, 0], S[:, 2, 0], S[:, 2, 1] = v[:, 2], -v[:, 1], v[:, 0]
    return S


def _pose(name: str, pose: object) -> pin.SE3:
    """``pose`` if it is a ``pinocchio.SE3`` with finite values, the identity if None."""
    if pose is None:
        return pin.SE3.Identity()
    if not isinstance(pose, pin.SE3):
        raise InvalidConfigurationError(
            f"{name} must be a pinocchio.SE3 (or None), got {type(pose).__name__}"
        )
    if not np.all(np.isfinite(pose.homogeneous)):
        raise InvalidConfigurationError(f"{name} holds NaN or inf; all must be finite")
    return pose


def _float_array(name: str, values: object) -> NDArray[np.float64]:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise InvalidConfigurationError(
            f"{name} must be numbers, got {type(values).__name__}"
        ) from None


def _random_rotation(rng: np.random.Generator) -> pin.SE3:
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    return pin.XYZQUATToSE3(np.concatenate([np.zeros(3), quat]))


def _frame_id(model: pin.Model, link: str) -> int:
    # BODY only: a joint of the same name must not stand in for a link.
    if not model.existFrame(link, pin.FrameType.BODY):
        links = sorted(f.name for f in model.frames if f.type == pin.FrameType.BODY)
        raise HandModelError(f"tip link {link!r} is not in the URDF; its links are {links}")
    return int(model.getFrameId(link, pin.FrameType.BODY))


def _read_urdf(description: HandDescription) -> bytes:
    urdf = description.urdf_path
    if not urdf.is_file():
        raise HandModelError(f"URDF of hand {description.name!r} not found: {shown(urdf)}")
    try:
        return urdf.read_bytes()
    except OSError as exc:
        raise HandModelError(f"cannot read URDF {shown(urdf)}: {exc.strerror}") from exc


def _build_models(description: HandDescription, urdf: str) -> tuple[pin.Model, pin.GeometryModel]:
    """Pinocchio's model and collision geometry from the checked URDF text.

    Built from the text whose bytes the digest hashes (not from the path again), so the hand
    is the one its digest names. Relative mesh paths resolve in the URDF's folder. An error the
    URDF parser only logs (it then drops the element) fails the load too.
    """
    dirs = [str(p) for p in (*description.package_dirs, description.urdf_path.parent)]
    failure = ""
    with native_stderr() as log:
        try:
            model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer(), "wrist", True)
            geometry = pin.buildGeomFromUrdfString(
                model, urdf, pin.GeometryType.COLLISION, None, dirs
            )
        except (ValueError, RuntimeError, OSError) as exc:
            failure = str(exc)
    errors = [shown(line.strip()) for line in log if line.startswith("Error:")]
    if failure or errors:
        reasons = "; ".join(dict.fromkeys(errors[:4] + [native_message(failure)] * bool(failure)))
        raise HandModelError(
            f"URDF {shown(description.urdf_path)} does not load in Pinocchio: {reasons}"
        )
    for line in log:
        print(shown(line), file=sys.stderr)
    return model, geometry


def check_made_for(
    hand: Hand,
    what: str,
    made_for: str,
    digest: str,
    error: type[SahGraspError],
    remedy: str,
) -> None:
    """Raise ``error`` unless data ``what`` made for hand ``made_for`` (``digest``) fits ``hand``.

    Args:
        hand: The hand the data is about to be used with.
        what: What the data is, for the message (``"sequence"``, ``"grasp database"``).
        made_for: Name of the hand the data was made for.
        digest: That hand's :meth:`HandDescription.digest`.
        error: The error type to raise.
        remedy: How to make data for ``hand`` (the message's last clause).
    """
    found = hand.description.digest()
    if found != digest:
        raise error(
            f"{what} made for hand {made_for!r} (digest {digest[:12]}) cannot be used with hand "
            f"{hand.description.name!r} (digest {found[:12]}); {remedy}"
        )


def load_hand(hand: str | os.PathLike[str] | HandDescription) -> Hand:
    """Build a :class:`Hand` from a built-in name, a hand-description JSON path, or a description.

    Args:
        hand: A registered hand's name (:data:`sahgrasp.model.hands.HANDS`: ``"sah"``,
            ``"allegro"`` and any added), a path to a description JSON, or a HandDescription.

    Raises:
        HandModelError: Unknown name, missing, unreachable (a loop of links, a name too long) or
            malformed description or URDF, missing tip link.
    """
    if isinstance(hand, HandDescription):
        return Hand(hand)
    text = str(hand)
    if hand_entry(text) is not None:
        return Hand(_registered_description(text))
    path = Path(text)
    if not path.suffix:
        raise HandModelError(
            f"unknown hand {shown(text)!r}: use one of {list(BUILTIN_HANDS)} or the path of a "
            "hand description JSON file"
        )
    _check_reachable(path)
    if path.suffix.lower() == ".urdf":
        raise HandModelError(
            f"{shown(path)} is a URDF; give the path of a hand description JSON that names it "
            "(its fingers, tip links and fingertip radius: see docs/how-to/add-a-hand.md)"
        )
    return Hand(HandDescription.from_json(path))


def _registered_description(name: str) -> HandDescription:
    """The description the registry's entry ``name`` builds, checked to be one."""
    description = HANDS.lookup(name).build()
    if not isinstance(description, HandDescription):
        raise HandModelError(
            f"hand {name!r}: its registered builder returned {type(description).__name__}, "
            "not a HandDescription"
        )
    if description.name != name:
        raise HandModelError(
            f"hand {name!r}: its registered builder returned a description named "
            f"{description.name!r}; the names must agree (the shipped data is found by name)"
        )
    return description


def _check_reachable(path: Path) -> None:
    """Raise unless ``path`` names an existing file, saying why not in one line."""
    where = f"hand description {shown_path(path)}"
    remedy = f"give {' or '.join(map(repr, BUILTIN_HANDS))} or the path of a hand description JSON"
    try:
        if "\0" in str(path):
            raise ValueError("embedded null byte")
        info = os.stat(path)
    except ValueError:  # a NUL byte or a lone surrogate: no file has that name
        raise HandModelError(f"{where} is not a valid file name; {remedy}") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise HandModelError(f"{where} is a loop of symbolic links; {remedy}") from None
        if exc.errno in (errno.ENOENT, errno.ENOTDIR):
            raise HandModelError(f"{where} not found; {remedy}") from None
        if exc.errno == errno.ENAMETOOLONG:
            raise HandModelError(f"{where} is a path too long for the file system") from None
        raise HandModelError(f"cannot read {where}: {exc.strerror or exc}") from None
    if not stat.S_ISREG(info.st_mode):
        raise HandModelError(f"{where} is not a regular file (a folder, pipe or device); {remedy}")
