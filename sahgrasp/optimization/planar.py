"""The planar three-finger hand of the atlas paper (Fig. 8, Eqs. (19)-(25)) as a grasp manifold.

Configuration ``x`` (n = 19), in this order:

- ``x[0:12]``: the unit vectors ``v_{i,j}`` of the six phalanges (finger i = 1..3, phalanx
  j = 1, 2), global orientation in the palm frame (Eq. (19));
- ``x[12:14]``: the object position ``t_o`` [m]; ``x[14:16]``: its orientation
  ``v_o = (s_o, c_o)`` (Eq. (20));
- ``x[16:19]``: the contact parameters ``u_i`` [rad], the angle of the contact on circle i
  (Eq. (24)).

``F(x) = 0`` (Eq. (9)) has 16 equations: six of Eq. (19), one of Eq. (20), the contact points
``q_i = o_i`` (Eqs. (7), (21), (23), two each) and the normal alignment ``m_i = -n_i`` (Eqs. (8),
(22), (25)). As both normals are unit vectors, the alignment is the single equation
``w(u_i) x v_{i,2} = 0`` (2-D cross product); of its two solution branches the one through the
initial grasp has ``w(u_i) = -v_{i,2}``. So ``t = 19 - 16 = 3``. Following Eq. (23) literally, the
angle ``u_i`` is measured in the palm frame and the arcs ``[a_i, b_i]`` are bounds on it.

The actuated joints are the six joint angles ``theta``: ``theta_{i,1}``, of phalanx 1 from the
palm's x axis, and ``theta_{i,2}``, of phalanx 2 relative to phalanx 1; the rate of the angle of a
vector ``v`` is ``v x dv / |v|^2``. Principal hand motions come from a PCA of random joint-angle
vectors (Section III), and Eq. (13) reads ``E_s^T (theta(x_h) - theta(x_1,h)) = 0``: in the
unit-vector coordinates themselves the least-variance directions are the radial ones (normal to the
unit circles), which would make Eq. (13) tangent to F at ``x_1``. ``s = t - k`` such equations
(Eq. (12)) reduce F to the k-manifold R of Eq. (11), which the atlas covers (Section IV).
:class:`PlanarGraspProblem` is a :class:`~sahgrasp.optimization.optimizer.GraspManifold`:
:func:`sahgrasp.optimization.optimizer.optimize` runs Algorithm 1 on it. Its manipulability indices
(:mod:`sahgrasp.quality.ellipsoids`) come from the tangent space of F, the actuated joint rates and
the object twist ``(vx, vy, omega)``.

Geometry (``DEFAULT_HAND``, SI units): fingers based at x = -0.08, 0 and 0.08 m on the palm (the
x axis), the outer ones with phalanges of 0.07 m and 0.035 m, the middle one of 0.035 m and
0.03 m; the object is three circles of radius 0.02 m, placed so that the posture of ``x_1`` (outer
fingers pinching the side lobes, the middle finger pushing the bottom lobe up; the object 0.07 m
above the palm) is a grasp. Joint limits, as box bounds on the phalanx vectors, keep the
proximal phalanges pointing up and the distal ones inwards (outer fingers) or up (middle finger).
Each contact may move by +-0.55 rad along its arc, which gives about the 750 charts of the paper
with r = 0.125 and epsilon = 0.4.
"""

from __future__ import annotations

import functools
from concurrent.futures import Executor
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sahgrasp.atlas._planar import features as features_of
from sahgrasp.atlas._planar import jacobian
from sahgrasp.core.errors import GraspSystemError
from sahgrasp.optimization.motions import principal_motions
from sahgrasp.optimization.optimizer import ChartChecks
from sahgrasp.quality.ellipsoids import Manipulability, full_rank_null_space, manipulability

__all__ = [
    "DEFAULT_HAND",
    "PlanarGraspProblem",
    "PlanarHand",
    "make_planar_problem",
    "random_hand_configurations",
]

FloatArray = NDArray[np.float64]

N_VARS = 19  # 12 phalanx vectors + t_o (2) + v_o (2) + u (3)
T_DIM = 3  # dimension of F (Section V)
_INF = np.inf
_V = slice(0, 12)
_TO = slice(12, 14)
_U = slice(16, 19)


def _unit(angle: ArrayLike) -> FloatArray:
    """``w(angle) = (cos, sin)`` (Eq. (24)), stacked on a last axis."""
    a = np.asarray(angle, dtype=np.float64)
    return np.stack((np.cos(a), np.sin(a)), axis=-1)


_NO_MOTIONS = np.zeros((0, 12))  # rates of no Eq. (13) rows: the grasp equations alone

_JOINTS_FROM_PHALANGES = np.kron(np.eye(3), [[1.0, 0.0], [-1.0, 1.0]])
"""``theta = D phi``: joint angles from absolute phalanx angles (distal relative to proximal)."""


def _angle_gradients(x: FloatArray) -> FloatArray:
    """Gradient of each phalanx's absolute angle by its vector (``v x dv / |v|^2``), (..., 12)."""
    vx, vy = x[..., 0:12:2], x[..., 1:12:2]
    norm2 = vx * vx + vy * vy
    grad = np.empty((*x.shape[:-1], 12))
    grad[..., 0::2] = -vy / norm2
    grad[..., 1::2] = vx / norm2
    return grad


@functools.cache
def _jacobian_layout(hand: PlanarHand) -> tuple[FloatArray, NDArray[np.int64]]:
    """Constant entries of the Jacobian of F (flattened 16 x 19) and where the others go.

    The variable entries are, in order: Eq. (19) (12), Eq. (20) (2), d/du_i of Eq. (7) (x for
    i = 1..3, then y), d/dv_{i,2} of Eq. (8) (x, then y) and d/du_i of Eq. (8).
    """
    jac = np.zeros((16, N_VARS))
    for i in range(3):
        contact = slice(7 + 2 * i, 9 + 2 * i)
        cx, cy = hand.centres[i]
        jac[contact, 4 * i : 4 * i + 2] = hand.phalanges[i, 0] * np.eye(2)  # Eq. (21)
        jac[contact, 4 * i + 2 : 4 * i + 4] = hand.phalanges[i, 1] * np.eye(2)
        jac[contact, _TO] = -np.eye(2)  # Eq. (23)
        jac[contact, 14] = (cy, -cx)  # -d(R c_i)/ds_o
        jac[contact, 15] = (-cx, -cy)  # -d(R c_i)/dc_o
    fingers = np.arange(3)
    rows = np.concatenate(
        (np.repeat(np.arange(6), 2), [6, 6], 7 + 2 * fingers, 8 + 2 * fingers, 13 + fingers,
         13 + fingers, 13 + fingers)
    )  # fmt: skip
    cols = np.concatenate(
        (np.arange(12), [14, 15], 16 + fingers, 16 + fingers, 4 * fingers + 2, 4 * fingers + 3,
         16 + fingers)
    )  # fmt: skip
    return jac.reshape(-1), (rows * N_VARS + cols).astype(np.int64)  # the kernel reads int64


_N_FEATURES = 50  # x (19), its squares (19), cos u, sin u, cos u v_2y, sin u v_2x (3 each)
_N_TURNS = 6  # the phalanx turns from x_1 of Eq. (13), after the grasp features


@functools.cache
def _grasp_residual_map(hand: PlanarHand) -> tuple[FloatArray, FloatArray]:
    """The grasp equations as ``features(x) @ M.T + c``: M (16, 50), c (16,) (see ``F``).

    The part linear in ``x`` is the constant part of the Jacobian (Eqs. (21), (23)); the rest:
    Eq. (19) (``|v_{i,j}|^2 - 1``), Eq. (20), the circle term ``-l_{i,3} w(u_i)`` of Eq. (23),
    the anchors ``a_i`` of Eq. (21) and Eq. (8) as ``w(u_i) x v_{i,2}``.
    """
    constant, _ = _jacobian_layout(hand)
    M, c = np.zeros((16, _N_FEATURES)), np.zeros(16)
    M[:, :N_VARS] = constant.reshape(16, N_VARS)
    pairs = np.concatenate((np.arange(12), [14, 15])).reshape(7, 2)  # v_{i,j} (6), then v_o
    M[np.arange(7)[:, None], N_VARS + pairs] = 1.0  # Eqs. (19), (20): squared norms
    c[:7] = -1.0
    fingers = np.arange(3)
    M[7 + 2 * fingers, 2 * N_VARS + fingers] = -hand.radii  # Eq. (23): l_{i,3} cos u_i
    M[8 + 2 * fingers, 2 * N_VARS + 3 + fingers] = -hand.radii  # l_{i,3} sin u_i
    c[7:13:2], c[8:13:2] = hand.anchors[:, 0], hand.anchors[:, 1]  # Eq. (21)
    M[13 + fingers, 2 * N_VARS + 6 + fingers] = 1.0  # Eq. (8): cos u v_2y - sin u v_2x
    M[13 + fingers, 2 * N_VARS + 9 + fingers] = -1.0
    return M, c


@dataclass(frozen=True, eq=False)
class PlanarHand:
    """Geometry of the hand and the object of Fig. 8 (SI units).

    Attributes:
        anchors: Palm anchor points ``a_i`` of the fingers, (3, 2) [m].
        phalanges: Lengths ``l_{i,1}, l_{i,2}``, (3, 2) [m].
        centres: Circle centres ``c_i`` in the object frame, (3, 2) [m].
        radii: Circle radii ``l_{i,3}``, (3,) [m].
        arcs: Contact parameter ranges ``[a_i, b_i]`` in the palm frame, (3, 2) [rad].
        posture: Absolute phalanx angles of the initial grasp ``x_1``, (3, 2) [rad].
        object_position: Object position ``t_o`` at ``x_1`` (unrotated object), (2,) [m].
        limits: Joint limits as box bounds on the phalanx vectors ``x[0:12]``: lower and upper,
            (2, 12); ``v_y >= sin(a)`` keeps a phalanx's angle within ``[a, pi - a]``.
    """

    anchors: FloatArray
    phalanges: FloatArray
    centres: FloatArray
    radii: FloatArray
    arcs: FloatArray
    posture: FloatArray
    object_position: FloatArray
    limits: FloatArray

    def initial_grasp(self) -> FloatArray:
        """The feasible grasp ``x_1`` (19,) the circles were placed for."""
        v = _unit(self.posture)
        u = np.arctan2(-v[:, 1, 1], -v[:, 1, 0])  # w(u_i) = -v_{i,2}
        return np.concatenate((v.reshape(-1), self.object_position, [0.0, 1.0], u))

    @classmethod
    def from_posture(
        cls,
        anchors: ArrayLike,
        phalanges: ArrayLike,
        radii: ArrayLike,
        angles: ArrayLike,
        object_position: ArrayLike,
        half_arc: float,
        limits: ArrayLike | None = None,
    ) -> PlanarHand:
        """Place the circles so that the hand at ``angles`` grasps the object (unrotated).

        Args:
            anchors: ``a_i``, (3, 2) [m].
            phalanges: ``l_{i,1}, l_{i,2}``, (3, 2) [m].
            radii: ``l_{i,3}``, (3,) [m].
            angles: Absolute angles of the phalanges, (3, 2) [rad].
            object_position: ``t_o`` at that grasp, (2,) [m].
            half_arc: Half-width of each arc around the nominal contact [rad].
            limits: Lower and upper bounds on the phalanx vectors, (2, 12); none if None.
        """
        a = np.asarray(anchors, dtype=np.float64)
        lengths = np.asarray(phalanges, dtype=np.float64)
        l3 = np.asarray(radii, dtype=np.float64)
        posture = np.asarray(angles, dtype=np.float64)
        t_o = np.asarray(object_position, dtype=np.float64)
        v = _unit(posture)  # (3, 2, 2)
        tips = a + lengths[:, :1] * v[:, 0] + lengths[:, 1:] * v[:, 1]  # Eq. (21)
        centres = tips + l3[:, None] * v[:, 1] - t_o  # Eq. (23) with w(u_i) = -v_{i,2}
        nominal = np.arctan2(-v[:, 1, 1], -v[:, 1, 0])
        arcs = nominal[:, None] + half_arc * np.array([-1.0, 1.0])
        box = np.array([[-np.inf] * 12, [np.inf] * 12]) if limits is None else np.asarray(limits)
        return cls(a, lengths, centres, l3, arcs, posture, t_o, box.astype(np.float64))


DEFAULT_HAND = PlanarHand.from_posture(
    anchors=[[-0.08, 0.0], [0.0, 0.0], [0.08, 0.0]],
    phalanges=[[0.07, 0.035], [0.035, 0.03], [0.07, 0.035]],
    radii=[0.02, 0.02, 0.02],
    angles=np.deg2rad([[95.0, 10.0], [60.0, 110.0], [85.0, 170.0]]),
    object_position=[0.0, 0.07],
    half_arc=0.55,
    limits=[
        # proximal phalanges point up (v_y >= 0.3), the outer distal ones inwards (v_x >= -0.3
        # on the left, <= 0.3 on the right), the middle distal one up (v_y >= 0)
        [-_INF, 0.3, -0.3, -_INF, -_INF, 0.3, -_INF, 0.0, -_INF, 0.3, -_INF, -_INF],
        [_INF, _INF, _INF, _INF, _INF, _INF, _INF, _INF, _INF, _INF, 0.3, _INF],
    ],
)
"""The hand used for the experiment of Section V (see the module docstring)."""


def random_hand_configurations(
    hand: PlanarHand, rng: np.random.Generator, count: int, spread: float
) -> FloatArray:
    """Random joint-angle vectors (count, 6) around the hand's initial posture.

    Gaussian with a random covariance (a random mixing matrix), so that the joints move in a
    correlated way and the principal motions are well defined; ``spread`` scales it [rad].
    """
    mixing = rng.normal(size=(6, 6)) / np.sqrt(6.0)
    joints = _JOINTS_FROM_PHALANGES @ hand.posture.reshape(6)
    return joints + spread * rng.normal(size=(count, 6)) @ mixing


@dataclass(frozen=True, eq=False)
class PlanarGraspProblem:
    """The feasible-grasp system of the planar hand plus the principal-motion constraints.

    Every method accepts one configuration (19,) or a batch (..., 19).

    Attributes:
        hand: Geometry.
        x1: The initial feasible grasp that Eq. (13) passes through, (19,).
        synergy: ``E_s``, the ``s`` least-variance hand motions in joint space, (6, s).
    """

    hand: PlanarHand
    x1: FloatArray
    synergy: FloatArray

    @property
    def dimension(self) -> int:
        """Dimension ``k`` of R: ``k = t - s`` (Eq. (12))."""
        return T_DIM - self.synergy.shape[1]

    @property
    def t(self) -> int:
        """Dimension of F: 19 variables, 16 equations."""
        return T_DIM

    @property
    def start(self) -> FloatArray:
        """The initial grasp ``x_1``, where the atlas starts."""
        return self.x1

    @property
    def stacked(self) -> bool:
        """True: :meth:`F` and :meth:`J` take a stack of points (the atlas's waves use that)."""
        return True

    @functools.cached_property
    def _residual_map(self) -> tuple[FloatArray, FloatArray]:
        """``F(x) = features @ M.T + c``: M (16 + s, 56) and c (16 + s,) (see :meth:`F`)."""
        grasp, offset = _grasp_residual_map(self.hand)
        s = self.synergy.shape[1]
        M = np.zeros((16 + s, _N_FEATURES + _N_TURNS))
        M[:16, :_N_FEATURES] = grasp
        M[16:, _N_FEATURES:] = (_JOINTS_FROM_PHALANGES.T @ self.synergy).T  # Eq. (13)
        return M, np.concatenate((offset, np.zeros(s)))

    @functools.cached_property
    def _jacobian_map(self) -> tuple[FloatArray, NDArray[np.int64], FloatArray]:
        """Constant part of J (flattened), where its variable entries go, and ``E_s^T J_a``.

        ``E_s^T J_a`` is ``rates * (angle gradients)`` with ``rates`` (s, 12) the joint motions
        per phalanx-vector component (see :func:`_angle_gradients`).
        """
        constant, where = _jacobian_layout(self.hand)
        s = self.synergy.shape[1]
        rows = 16 + np.arange(s)[:, None]
        motion_where = (rows * N_VARS + np.arange(12)).reshape(-1)
        rates = np.repeat(self.synergy.T @ _JOINTS_FROM_PHALANGES, 2, axis=1)
        full = np.concatenate((constant, np.zeros(s * N_VARS)))
        return full, np.concatenate((where, motion_where)).astype(np.int64), rates

    def grasp_residual(self, x: ArrayLike) -> FloatArray:
        """``F(x)`` of Eq. (9), (..., 16): Eqs. (19), (20), (7) with (21), (23) and (8)."""
        return self.F(x)[..., :16]

    def grasp_jacobian(self, x: ArrayLike) -> FloatArray:
        """Jacobian of :meth:`grasp_residual`, (..., 16, 19): a constant part plus 29 entries."""
        constant, where = _jacobian_layout(self.hand)
        return self._jacobian(x, constant, where, _NO_MOTIONS)

    def F(self, x: ArrayLike) -> FloatArray:
        """``R(x)`` of Eq. (11): F plus Eq. (13) on the joint angles, (..., 16 + s).

        Every equation is linear in a few features of ``x`` (``x``, its squares, ``cos u_i``,
        ``sin u_i``, two products and the phalanx turns from ``x_1``), so one evaluation is the
        features (compiled, ``atlas._planar.features``, but for numpy's arctan2) and one matrix
        product, which matters in Newton's method.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        M, offset = self._residual_map
        features = np.empty((*x.shape[:-1], _N_FEATURES + _N_TURNS))
        cosines = np.empty((*x.shape[:-1], _N_TURNS))
        turns = features[..., _N_FEATURES:]  # sines from the compiled kernel, then the turns
        features_of(x.reshape(-1, N_VARS), self.x1, features.reshape(-1, _N_FEATURES + _N_TURNS),
                    cosines.reshape(-1, _N_TURNS))  # fmt: skip
        np.arctan2(turns, cosines, out=turns)  # numpy's arctan2, as in _turns
        return features @ M.T + offset

    def J(self, x: ArrayLike) -> FloatArray:
        """Jacobian of :meth:`F`, (..., 16 + s, 19)."""
        return self._jacobian(x, *self._jacobian_map)

    def _jacobian(
        self, x: ArrayLike, constant: FloatArray, where: NDArray[np.int64], rates: FloatArray
    ) -> FloatArray:
        """The layout ``constant`` with the variable entries put at ``where``, (..., rows, 19).

        Compiled (``atlas._planar.jacobian``): the atlas asks for J at a few points at a time, where
        numpy's 20 array operations cost far more than the arithmetic (docs/methods/atlas.md).
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        rows = 16 + rates.shape[0]
        jac = np.empty((*x.shape[:-1], rows, N_VARS))
        flat = jac.reshape(-1, rows, N_VARS)  # a view: the kernel fills jac
        jacobian(x.reshape(-1, N_VARS), constant, where, self.hand.radii, rates, flat)
        return jac

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Box bounds on ``x``: the joint limits and the arcs ``[a_i, b_i]`` of the contacts."""
        lower, upper = np.full(N_VARS, -np.inf), np.full(N_VARS, np.inf)
        lower[_V], upper[_V] = self.hand.limits
        lower[_U], upper[_U] = self.hand.arcs[:, 0], self.hand.arcs[:, 1]
        return lower, upper

    def joint_angles(self, x: ArrayLike) -> FloatArray:
        """The six actuated joint angles (..., 6) in (-pi, pi] [rad], finger by finger."""
        v = np.asarray(x, dtype=np.float64)[..., _V].reshape(*np.shape(x)[:-1], 6, 2)
        theta = np.arctan2(v[..., 1], v[..., 0]) @ _JOINTS_FROM_PHALANGES.T
        return np.angle(np.exp(1j * theta))

    def joint_motion(self, x: ArrayLike) -> FloatArray:
        """Joint angles minus those of ``x_1`` (..., 6) [rad], smooth while under pi in size."""
        return self._turns(np.asarray(x, dtype=np.float64)) @ _JOINTS_FROM_PHALANGES.T

    def _turns(self, x: FloatArray) -> FloatArray:
        """Angle of each phalanx from its angle at ``x_1`` (..., 6) [rad]."""
        vx, vy = x[..., 0:12:2], x[..., 1:12:2]
        rx, ry = self.x1[0:12:2], self.x1[1:12:2]
        return np.arctan2(rx * vy - ry * vx, rx * vx + ry * vy)

    def joint_jacobian(self, x: ArrayLike) -> FloatArray:
        """``J_a``: joint angle rates from ``dx``, (..., 6, 19)."""
        x = np.asarray(x, dtype=np.float64)
        rate = np.zeros((*x.shape[:-1], 6, N_VARS))
        rate[..., :12] = np.repeat(_JOINTS_FROM_PHALANGES, 2, axis=1)
        rate[..., :12] *= _angle_gradients(x)[..., None, :]
        return rate

    def object_jacobian(self, x: ArrayLike) -> FloatArray:
        """``J_o``: object velocity ``(vx, vy, omega)`` from ``dx``, (..., 3, 19).

        ``omega = c_o ds_o - s_o dc_o`` for ``v_o = (s_o, c_o) = (sin, cos)`` of the angle.
        """
        x = np.asarray(x, dtype=np.float64)
        jac = np.zeros((*x.shape[:-1], 3, N_VARS))
        jac[..., 0, 12] = 1.0
        jac[..., 1, 13] = 1.0
        jac[..., 2, 14] = x[..., 15]
        jac[..., 2, 15] = -x[..., 14]
        return jac

    def manipulability(self, x: ArrayLike) -> Manipulability:
        """Manipulability ellipsoids at configurations ``x`` (..., 19) with the tangent of F.

        ``x`` must be regular points of F (the grasp Jacobian of full rank 16), as the chart
        centres of an atlas of R are: the tangent basis then comes from a QR, not an SVD.
        """
        x = np.asarray(x, dtype=np.float64)
        tangent = full_rank_null_space(self.grasp_jacobian(x))
        return manipulability(tangent, self.joint_jacobian(x), self.object_jacobian(x))

    def check_charts(self, centres: FloatArray, executor: Executor | None = None) -> ChartChecks:
        """The planar hand has no collision model: every chart centre is a candidate."""
        return ChartChecks.none(centres)


def make_planar_problem(
    k: int = 2,
    hand: PlanarHand = DEFAULT_HAND,
    samples: int = 500,
    spread: float = 0.5,
    seed: int = 0,
) -> PlanarGraspProblem:
    """The planar grasp problem with ``s = 3 - k`` principal-motion constraints (Eq. (12)).

    Args:
        k: Dimension of the explored set R, 1 <= k <= 3.
        hand: Geometry; its nominal posture is the initial grasp ``x_1``.
        samples: Number ``z`` of random hand configurations for the PCA.
        spread: Half-range of the random joint angles around the nominal ones [rad].
        seed: Seed of the random configurations.

    Raises:
        GraspSystemError: ``k`` is not 1, 2 or 3.
    """
    if k not in (1, 2, 3):
        raise GraspSystemError(f"k must be 1, 2 or 3 (t = {T_DIM}), got {k}")
    rng = np.random.default_rng(seed)
    motions = principal_motions(random_hand_configurations(hand, rng, samples, spread))
    synergy = motions.constraints(T_DIM - k).T  # s = t - k least-variance motions, Eq. (12)
    return PlanarGraspProblem(hand=hand, x1=hand.initial_grasp(), synergy=synergy)
