"""Initial hand configurations of Algorithm 1 (Claret & Suárez Sections 3.1 and 3.2).

* :class:`PoseBasis` -- the PCA of a set S of sampled hand poses: mean ``m``, principal directions
  ``c_1, c_2`` and deviations ``sigma_1, sigma_2`` (Eq. (11)). Poses live in the paper's
  ``Q`` space (Eq. (4)): every finger joint including the coupled (mimic) ones, plus the virtual
  contact joints -- 25 values for the SAH.
* :class:`Sequence` -- the lambdas ``SEQ = (lambda_1, ..., lambda_imax)`` and the basis they refer
  to, with the hand they were made for; read and written as JSON.
* :func:`hang_from_thumb` -- ``Obtain_Initial_Conf``: the pose ``Q_i`` plus the wrist placed so that
  the thumb satisfies its contact (Eq. (3)) and the rotation ``psi`` about the thumb normal that
  aligns the index-ring direction with the target's.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.errors import SequenceFileError
from sahgrasp.core.fileio import write_json_atomic
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import Hand, check_made_for
from sahgrasp.model.hands import data_file, hand_entry

__all__ = [
    "PAPER_TABLE1_LAMBDAS",
    "PoseBasis",
    "Sequence",
    "cross3",
    "cross_floats",
    "default_sequence",
    "expansion_matrix",
    "hang_from_thumb",
    "pose_basis",
    "rotation_aligning_x",
]

PAPER_TABLE1_LAMBDAS: tuple[tuple[float, float], ...] = (
    (0.517, 0.483), (0.793, 0.552), (0.310, 0.690), (0.0, 0.517),
    (0.690, 0.448), (0.138, 0.241), (0.034, 0.827), (0.655, 0.241),
    (0.690, 0.0), (0.690, 0.448), (0.724, 0.276), (0.276, 0.827),
)  # fmt: skip
"""Table 1 of Claret & Suárez: (lambda^1, lambda^2) of the 12 initial poses."""

PCA_SAMPLES = 10_000
PCA_SEED = 20120101


def expansion_matrix(hand: Hand) -> NDArray[np.float64]:
    """Matrix ``E`` mapping the coordinates ``Hand.finger_part(q)`` to the paper's pose ``Q``.

    ``Q`` lists every coordinate and then every mimic joint (``multiplier * leader``; offsets are
    added by :meth:`PoseBasis.coordinates`), so for the SAH ``E`` is 25 x 21.
    """
    n = len(hand.coordinate_names)
    rows = [np.eye(n)]
    for leader, scale, _ in hand.mimic_joints.values():
        row = np.zeros((1, n))
        row[0, hand.coordinate_index(leader)] = scale
        rows.append(row)
    return np.vstack(rows)


def _mimic_offsets(hand: Hand) -> NDArray[np.float64]:
    n = len(hand.coordinate_names)
    offsets = [offset for _, _, offset in hand.mimic_joints.values()]
    return np.concatenate([np.zeros(n), np.asarray(offsets, dtype=np.float64)])


@dataclass(frozen=True)
class PoseBasis:
    """PCA of sampled hand poses in ``Q`` space (Eq. (11)).

    Attributes:
        mean: ``m``, shape (dim Q,).
        directions: ``c_1, c_2`` as rows, unit vectors, shape (2, dim Q).
        sigmas: ``sigma_1, sigma_2``, standard deviations of S along them [rad].
    """

    mean: NDArray[np.float64]
    directions: NDArray[np.float64]
    sigmas: NDArray[np.float64]

    def pose(self, lambdas: tuple[float, float] | NDArray[np.float64]) -> NDArray[np.float64]:
        """Pose ``Q_i = m + 3 sigma_1 (2 lambda^1 - 1) c_1 + 3 sigma_2 (2 lambda^2 - 1) c_2``.

        Eq. (11).
        """
        lam = np.asarray(lambdas, dtype=np.float64)
        return np.asarray(self.mean + (3.0 * self.sigmas * (2.0 * lam - 1.0)) @ self.directions)

    def coordinates(self, hand: Hand, lambdas: tuple[float, float]) -> NDArray[np.float64]:
        """Coordinates ``Hand.finger_part(q)`` of pose ``Q_i``, clamped to the joint limits.

        ``Q_i`` lies in the span of the sampled poses, where coupled joints are equal, so reading
        the independent entries loses nothing. Extreme lambdas (+-3 sigma) can leave the joint
        range: those coordinates are clamped to their limits.
        """
        n = len(hand.coordinate_names)
        coords = self.pose(lambdas)[:n]
        return np.clip(coords, hand.lower, hand.upper)

    def to_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            "mean": self.mean.tolist(),
            "directions": self.directions.tolist(),
            "sigmas": self.sigmas.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PoseBasis:
        """Inverse of :meth:`to_dict`."""
        return cls(
            np.asarray(data["mean"], dtype=np.float64),
            np.asarray(data["directions"], dtype=np.float64),
            np.asarray(data["sigmas"], dtype=np.float64),
        )


def pose_basis(hand: Hand, samples: int = PCA_SAMPLES, seed: int = PCA_SEED) -> PoseBasis:
    """PCA of ``samples`` hand poses drawn uniformly within the joint limits, collision-free.

    S is sampled as the paper says ("randomly generated"): every independent finger joint and
    virtual contact joint uniform in its range, coupled joints following their leader, and only
    poses without self-collision kept (they are the poses an initial configuration should
    resemble). The PCA is the eigen-decomposition of the covariance of the mean-centred ``Q``.
    """
    rng = np.random.default_rng(seed)
    E, offsets = expansion_matrix(hand), _mimic_offsets(hand)
    X = np.array(
        [
            hand.finger_part(hand.random_configuration(rng, collision_free=True))
            for _ in range(samples)
        ]
    )
    Q = X @ E.T + offsets
    mean = Q.mean(axis=0)
    eigvals, eigvecs = np.linalg.eigh(np.cov(Q - mean, rowvar=False))
    order = np.argsort(eigvals)[::-1][:2]
    directions = eigvecs[:, order].T
    # Sign convention: the largest component of each direction is positive (reproducible files).
    signs = np.sign(directions[np.arange(2), np.argmax(np.abs(directions), axis=1)])
    return PoseBasis(mean, directions * signs[:, None], np.sqrt(eigvals[order]))


@dataclass(frozen=True)
class Sequence:
    """A sequence of initial poses for one hand (Claret & Suárez Section 3.2).

    Attributes:
        hand: Hand name.
        hand_digest: :meth:`HandDescription.digest` of the hand it was made for.
        basis: The PCA basis the lambdas refer to.
        lambdas: ``(lambda^1, lambda^2)`` per initial configuration, in order.
        source: ``"paper-table1"`` or ``"search"``.
        meta: Search settings (N, M, seed, ...) when ``source == "search"``.
    """

    hand: str
    hand_digest: str
    basis: PoseBasis
    lambdas: tuple[tuple[float, float], ...]
    source: str = "search"
    meta: dict[str, Any] | None = None

    def check_hand(self, hand: Hand) -> None:
        """Raise :class:`SequenceFileError` unless this sequence was made for ``hand``."""
        check_made_for(
            hand, "sequence", self.hand, self.hand_digest, SequenceFileError,
            "compute one with `sahgrasp sequence --hand ...`",
        )  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """JSON form (``lambdas`` is the list of chosen pairs)."""
        return {
            "format": "sahgrasp-sequence-1",
            "hand": self.hand,
            "hand_digest": self.hand_digest,
            "source": self.source,
            "lambdas": [list(pair) for pair in self.lambdas],
            "basis": self.basis.to_dict(),
            "meta": self.meta or {},
        }

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write atomically as JSON."""
        write_json_atomic(path, self.to_dict())

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> Sequence:
        """Read a sequence file, raising :class:`SequenceFileError` if it is not one."""
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as exc:
            raise SequenceFileError(f"cannot read sequence file {path}: {exc}") from exc
        return cls.from_dict(data, str(path))

    @classmethod
    def from_dict(cls, data: Any, origin: str = "sequence") -> Sequence:
        """Build from the JSON form, raising :class:`SequenceFileError` on anything malformed."""
        try:
            if data.get("format") != "sahgrasp-sequence-1":
                raise ValueError("format is not sahgrasp-sequence-1")
            basis = PoseBasis.from_dict(data["basis"])
            lambdas = tuple((float(a), float(b)) for a, b in data["lambdas"])
            if not lambdas or not all(0.0 <= v <= 1.0 for pair in lambdas for v in pair):
                raise ValueError("lambdas must be a non-empty list of pairs in [0, 1]")
            if basis.directions.shape != (2, basis.mean.size) or basis.sigmas.shape != (2,):
                raise ValueError("basis shapes disagree")
            return cls(
                str(data["hand"]), str(data["hand_digest"]), basis, lambdas,
                str(data.get("source", "search")), dict(data.get("meta", {})),
            )  # fmt: skip
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise SequenceFileError(
                f"{origin} is not a valid sahgrasp sequence ({exc}); it needs format, hand, "
                "hand_digest, lambdas and basis {mean, directions, sigmas}"
            ) from exc


def default_sequence(hand: Hand) -> Sequence:
    """The sequence the IK uses by default for ``hand``, built once per hand (``hand.cache``).

    The package ships sequences computed by the offline search in ``sahgrasp/data/sequences``,
    named by the hand's registry entry (:data:`sahgrasp.model.hands.HANDS`); for a hand without
    one (or whose shipped file was made for another version of the hand), the paper's Table 1
    lambdas are applied to this hand's own PCA basis.
    """
    return hand.cache.get("default_sequence", lambda: _default_sequence(hand))


def _default_sequence(hand: Hand) -> Sequence:
    digest = hand.description.digest()
    entry = hand_entry(hand.description.name)
    sequence = None
    if entry is not None and entry.sequence is not None:
        shipped = data_file(entry.sequence)
        if shipped.is_file():
            data = json.loads(shipped.read_text(encoding="utf-8"))
            candidate = Sequence.from_dict(data, "shipped")
            if candidate.hand_digest == digest:
                sequence = candidate
    if sequence is None:
        sequence = Sequence(
            hand.description.name, digest, pose_basis(hand), PAPER_TABLE1_LAMBDAS, "paper-table1"
        )
    return sequence


def cross3(a: NDArray[np.float64], b: NDArray[np.float64]) -> NDArray[np.float64]:
    """``a x b`` of two 3-vectors.

    In Python floats: ``np.cross``'s wrapper, and even the fancy-indexed products that replaced
    it, cost ten times the arithmetic on 3-vectors.
    """
    return np.array(cross_floats(a.tolist(), b.tolist()))


def cross_floats(a: list[float], b: list[float]) -> list[float]:
    """``a x b`` of two 3-vectors held as Python floats."""
    (a0, a1, a2), (b0, b1, b2) = a, b
    return [a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0]


def rotation_aligning_x(direction: NDArray[np.float64]) -> NDArray[np.float64]:
    """A rotation matrix whose x axis is the unit vector ``direction``."""
    x = direction / math.sqrt(float(direction.dot(direction)))
    y = cross3(x, _X_AXIS if abs(x[0]) < 0.9 else _Y_AXIS)
    y /= math.sqrt(float(y.dot(y)))
    return np.array([x, y, cross3(x, y)]).T


_X_AXIS, _Y_AXIS = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])


def hang_from_thumb(
    hand: Hand,
    coordinates: NDArray[np.float64],
    target: GraspTarget,
    psi: float | None = None,
) -> tuple[NDArray[np.float64], float]:
    """``Obtain_Initial_Conf``: joint coordinates + wrist hung from the thumb contact (Eq. (3)).

    The wrist is placed so that the thumb's contact point is ``p_T*`` and its outward normal is
    ``-n_T*`` (so ``r_T = r_T*``). The remaining rotation ``psi`` about the thumb normal is
    ``psi`` if given, else the one that minimises the angle between the projections on the plane
    ``Pi_T`` of ``p_R* - p_I*`` and ``p_R - p_I`` (first and last non-thumb fingers). The hand hangs
    from the first of its fingers that the target constrains (the thumb, normally).

    Returns:
        The configuration ``q`` and ``psi`` [rad].
    """
    thumb = next(f for f in hand.fingers if f in target.fingers)
    q = hand.configuration(None, coordinates)
    T_palm_thumb = hand.contact_placement(q, thumb)
    contact = target.contact(thumb)
    R_align = rotation_aligning_x(-contact.normal)
    if psi is None:
        psi = _best_psi(hand, q, T_palm_thumb, R_align, thumb, target)
    T_world_thumb = pin.SE3(R_align @ _rot_x(psi), contact.point)
    hand.wrist_part(q)[:] = pin.SE3ToXYZQUAT(T_world_thumb * T_palm_thumb.inverse())
    return q, psi


def _best_psi(
    hand: Hand,
    q_palm: NDArray[np.float64],
    T_palm_thumb: pin.SE3,
    R_align: NDArray[np.float64],
    thumb: str,
    target: GraspTarget,
) -> float:
    others = [f for f in hand.fingers if f in target.fingers and f != thumb]
    first, last = (others[0], others[-1]) if len(others) > 1 else (thumb, others[0])
    p_thumb = target.contact(thumb).point
    state = hand.contact_state(q_palm)
    d_palm = state.points[hand.fingers.index(last)] - state.points[hand.fingers.index(first)]
    # Where that direction points in world when psi = 0; rotating by psi turns it about the axis.
    T0 = pin.SE3(R_align, p_thumb) * T_palm_thumb.inverse()
    v2 = T0.rotation @ d_palm
    v1 = target.contact(last).point - target.contact(first).point
    axis = R_align[:, 0]
    v1p, v2p = v1 - (v1 @ axis) * axis, v2 - (v2 @ axis) * axis
    return math.atan2(float(axis @ cross3(v2p, v1p)), float(v2p @ v1p))


def _rot_x(angle: float) -> NDArray[np.float64]:
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
