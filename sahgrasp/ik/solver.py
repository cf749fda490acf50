"""Algorithm 1 of Claret & Suárez: fingertip contacts -> wrist pose and joint values.

Two inner solvers share the outer loop (initial configurations from a :class:`Sequence`, or random
ones) and the acceptance test (Eq. (9) for every finger, joints within limits, no self-collision):

* ``method="paper"`` -- the paper's step. The hand hangs from the thumb contact (Eq. (3)); the
  unknowns are ``C' = (psi, Q)`` and the step is ``Delta C' = J^+ alpha (P*' - P'_k)``
  (Eqs. (7)-(8)).
  Our model keeps coupled joints equal by construction (Pinocchio mimic joints), so ``C'`` holds the
  independent coordinates; the pseudo-inverse is weighted so that it equals the paper's augmented
  22 x 26 pseudo-inverse whenever that matrix has full row rank (each coupled joint counts in the
  step's norm once per joint it drives). Joint values leaving their range are clamped to it.
* ``method="auto"`` -- the same structure with a better inner loop: a free wrist (all four
  contacts in the residual), Levenberg-Marquardt with adaptive damping, joint limits as an active
  set, early abandonment of starts that stop reducing the error, and refinement of a converged
  configuration to ``refine_m``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Literal, get_args

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray

from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.ik.compiled import OUTCOMES, compiled_tree, near_pairs, self_collides, tree_joint
from sahgrasp.ik.initial import Sequence, default_sequence, expansion_matrix, hang_from_thumb
from sahgrasp.ik.learned import GraspDatabase, contact_key, default_database
from sahgrasp.ik.obstacle import Obstacle, checker_of
from sahgrasp.ik.starts import initial_lambdas
from sahgrasp.model.contacts import GraspTarget
from sahgrasp.model.hand import ContactState, Hand
from sahgrasp.model.hands import DEFAULT_HAND

if TYPE_CHECKING:
    from sahgrasp.collision.hand_self import Penetration
    from sahgrasp.objects import GraspObject

__all__ = [
    "INNER_SOLVERS",
    "REASONS",
    "Attempt",
    "AttemptFn",
    "ContactProblem",
    "IKResult",
    "IKSettings",
    "Init",
    "InnerSolver",
    "Method",
    "Reason",
    "run_algorithm1",
    "solve_ik",
    "stack_rows",
]

Method = Literal["auto", "paper"]
"""Inner solver of Algorithm 1."""
Init = Literal["sequence", "random", "learned"]
"""Where the initial configurations come from."""
Reason = Literal[
    "converged", "max_inits", "no_progress", "collision", "object_collision", "invalid_input"
]
"""Why a solve ended: ``converged`` on success, otherwise why no start was accepted."""
REASONS: tuple[Reason, ...] = get_args(Reason)
"""Values of :attr:`IKResult.reason`."""
MAX_INITS_LIMIT = 1000
"""Largest accepted ``IKSettings.max_inits``."""
MAX_ITERATIONS_LIMIT = 1_000_000
"""Largest accepted ``max_iterations``, ``stall_iterations`` and ``repair_iterations``: far above
any useful value (the IK converges in tens of iterations or not at all), and within the C
solver's ``int``."""


@dataclass(frozen=True)
class IKSettings:
    """Parameters of Algorithm 1 (defaults: the paper's, plus measured choices; docs/methods/ik.md).

    Attributes:
        method: ``"auto"`` (default) or ``"paper"``.
        init: ``"learned"`` (default: the nearest grasps of a database first, then the
            sequence; see :mod:`sahgrasp.ik.learned`; the sequence alone for a hand without a
            database), ``"sequence"`` (the offline sequence) or ``"random"`` (random lambdas,
            Fig. 9).
        learned_starts: With ``init="learned"``, how many database neighbours come first.
        max_inits: ``i_max``, initial configurations tried (1 .. :data:`MAX_INITS_LIMIT`).
        max_iterations: ``k_max``, Jacobian iterations per initial configuration
            (1 .. :data:`MAX_ITERATIONS_LIMIT`, as the two other iteration counts).
        d_min_m: Eq. (9) tolerance on contact points and sphere centres [m].
        s_min_m: Eq. (10) threshold of "no progress" [m].
        stall_iterations: ``n`` of Step 13: consecutive iterations without progress.
        alpha: Step gain of the paper's method (``Delta P' = alpha (P*' - P'_k)``).
        refine_m: The auto method keeps iterating a converged start down to this error [m].
        repair_iterations: Auto method: steps allowed to push a converged but self-colliding
            configuration out of collision along the solution set.
        collision_margin_m: Clearance those steps aim for [m].
        seed: Seed (>= 0) of the random initial configurations; each problem draws its own
            from this seed and its content (:func:`sahgrasp.ik.starts.problem_seed`).
        record_history: Keep every iterate of the returned attempt (for animation).
    """

    method: Method = "auto"
    init: Init = "learned"
    max_inits: int = 12
    learned_starts: int = 2
    max_iterations: int = 100
    d_min_m: float = 1.5e-3
    s_min_m: float = 1e-3
    stall_iterations: int = 10
    alpha: float = 1.0
    refine_m: float = 1e-5
    repair_iterations: int = 10
    collision_margin_m: float = 1e-3
    seed: int = 0
    record_history: bool = False

    def __post_init__(self) -> None:
        for name, valid in (("method", get_args(Method)), ("init", get_args(Init))):
            if getattr(self, name) not in valid:
                raise InvalidSettingsError(
                    f"{name} must be one of {list(valid)}, got {getattr(self, name)!r}"
                )
        _check_int("max_inits", self.max_inits, 1, MAX_INITS_LIMIT)
        _check_int("learned_starts", self.learned_starts, 0, MAX_INITS_LIMIT)
        for name in ("max_iterations", "stall_iterations", "repair_iterations"):
            _check_int(name, getattr(self, name), 1, MAX_ITERATIONS_LIMIT)
        _check_int("seed", self.seed, 0)
        for name in ("d_min_m", "s_min_m", "alpha", "refine_m", "collision_margin_m"):
            value = getattr(self, name)
            if not _is_real(value) or not (math.isfinite(value) and value > 0.0):
                raise InvalidSettingsError(f"{name} must be a finite number > 0, got {value!r}")


def _is_real(value: object) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _check_int(name: str, value: Any, low: int, high: int | None = None) -> None:
    """Raise :class:`InvalidSettingsError` unless ``value`` is an integer in ``[low, high]``."""
    integer = isinstance(value, int | np.integer) and not isinstance(value, bool)
    if integer and low <= int(value) and (high is None or int(value) <= high):
        return
    bounds = f">= {low}" if high is None else f"between {low} and {high}"
    raise InvalidSettingsError(f"{name} must be an integer {bounds}, got {value!r}")


@dataclass(frozen=True)
class IKResult:
    """Outcome of :func:`solve_ik`. ``q`` is the solution, or the best configuration found.

    Attributes:
        name: Problem name.
        success: Every contact within ``d_min``, limits respected, no self-collision and, with
            an obstacle, no link inside it (contact fingertips: not deeper than ``d_min``).
        reason: One of :data:`REASONS`.
        q: Configuration (wrist + independent coordinates), see :class:`Hand`.
        position_errors_m: ``|p_i - p_i*|`` per finger [m].
        centre_errors_m: ``|r_i - r_i*|`` per finger [m].
        inits_used: Initial configurations generated.
        iterations: Jacobian iterations over all initial configurations.
        time_s: Wall time [s] of the whole solve: the problem's set-up, every start with its
            collision checks and repairs, and the result's errors and clearance (not the
            one-time loading of the hand's shipped sequence and database).
        collision_free: No self-collision at ``q``.
        fingers: Finger names, the order of the error arrays.
        attempts: How each initial configuration ended.
        attempt_seconds: Wall time [s] from the start to the end of each attempt.
        history: Iterates of the returned attempt when recorded, initial configuration first.
        object_clearance_m: With an obstacle, the smallest signed distance [m] from a link to it
            at ``q`` (negative: inside; contact fingertips within ``d_min`` left out); None
            without.
        closest_link: With an obstacle, the link at ``object_clearance_m``; None without.
    """

    name: str
    success: bool
    reason: Reason
    q: NDArray[np.float64]
    position_errors_m: NDArray[np.float64]
    centre_errors_m: NDArray[np.float64]
    inits_used: int
    iterations: int
    time_s: float
    collision_free: bool
    fingers: tuple[str, ...]
    attempts: tuple[str, ...] = ()
    attempt_seconds: tuple[float, ...] = ()
    history: tuple[NDArray[np.float64], ...] | None = field(default=None, repr=False)
    object_clearance_m: float | None = None
    closest_link: str | None = None

    @property
    def max_error_m(self) -> float:
        """Largest contact-point or centre error [m]."""
        return float(max(self.position_errors_m.max(), self.centre_errors_m.max()))

    @property
    def T_world_palm(self) -> pin.SE3:
        """Wrist pose of the result."""
        return Hand.wrist_pose(self.q)

    def to_dict(self, hand: Hand) -> dict[str, Any]:
        """The results-file entry (docs/how-to/file-formats.md); clearance only with an obstacle."""
        entry = {
            "name": self.name,
            "success": self.success,
            "reason": self.reason,
            "inits_used": self.inits_used,
            "iterations": self.iterations,
            "time_ms": self.time_s * 1e3,
            "max_position_error_mm": float(self.position_errors_m.max() * 1e3),
            "max_centre_error_mm": float(self.centre_errors_m.max() * 1e3),
            "collision_free": self.collision_free,
            "wrist": {"xyz": self.q[:3].tolist(), "quat": self.q[3:7].tolist()},
            "joints": hand.joint_values(self.q),
            "contact_params": {f: list(v) for f, v in hand.contact_parameters(self.q).items()},
        }
        if self.object_clearance_m is not None:
            entry["object_clearance_mm"] = self.object_clearance_m * 1e3
            entry["closest_link"] = self.closest_link
        return entry


@dataclass(frozen=True)
class Attempt:
    """How one initial configuration ended: its final ``q``, outcome, iterations and error [m].

    A record: the outer loop derives the checked attempt with :func:`dataclasses.replace`.
    """

    q: NDArray[np.float64]
    outcome: str
    iterations: int
    error_m: float
    history: list[NDArray[np.float64]] | None
    seconds: float = 0.0


class ContactProblem:
    """Targets of the constrained fingers (hand order) and the residual of a configuration.

    Args:
        hand: The hand.
        target: One contact per finger that touches the object (at least two, the thumb
            among them when the hand has one, :meth:`GraspTarget.check_fingers`).
        free_fingers: Fingers deliberately left without a contact (e.g. the ring finger of a
            three-finger grasp); every finger without a contact in ``target`` is free anyway
            (:attr:`free_fingers` holds them all, in hand order).
        obstacle: An object no link may enter (the constrained fingers' tips touch it).
        allowance_m: How deep a contact fingertip sphere may enter the obstacle [m].
    """

    def __init__(
        self,
        hand: Hand,
        target: GraspTarget,
        free_fingers: tuple[str, ...] = (),
        obstacle: GraspObject | None = None,
        allowance_m: float = IKSettings.d_min_m,
    ) -> None:
        unknown = [f for f in free_fingers if f not in hand.fingers]
        if unknown:
            raise InvalidTargetError(
                f"free finger(s) {unknown} unknown; valid: {list(hand.fingers)}"
            )
        target.check_fingers(hand.fingers)
        touching = [f for f in free_fingers if f in target.fingers]
        if touching:
            raise InvalidTargetError(
                f"grasp {target.name!r}: finger(s) {touching} have a contact and are given as "
                "free fingers too; a free finger has no contact"
            )
        constrained = [f for f in hand.fingers if f in target.fingers]
        self.free_fingers = target.free_fingers(hand.fingers)
        self.hand = hand
        self.target = target
        self.fingers = tuple(constrained)
        self.rows = np.array([hand.fingers.index(f) for f in constrained], dtype=np.intp)
        by_finger = {c.finger: c for c in target.contacts}
        contacts = [by_finger[f] for f in constrained]
        self.points = np.array([c.point for c in contacts])
        self.normals = np.array([c.normal for c in contacts])
        self.centres = self.points + hand.radius_m * self.normals  # ContactTarget.centre, stacked
        # The targets in the order of Hand.contact_stack: (p_i*, r_i*) per constrained finger.
        self.target_stack = np.concatenate([self.points, self.centres], axis=1).ravel()
        self.obstacle = (
            None if obstacle is None else Obstacle(hand, obstacle, self.fingers, allowance_m)
        )
        # The last configuration checked and its verdict: the inner solver checks a converged
        # start and the outer loop checks it again (Step 8); the second check is free.
        self._checked: tuple[bytes, Literal["collision", "object_collision"] | None] | None = None

    def collision(self, q: NDArray[np.float64]) -> Literal["collision", "object_collision"] | None:
        """Why ``q`` is rejected, None if it is not.

        A configuration inside the obstacle is ``object_collision`` even if it also collides with
        itself: the collision repair often trades one for the other, and the object is the reason
        the problem has no solution.
        """
        key = q.tobytes()
        if self._checked is not None and self._checked[0] == key:
            return self._checked[1]
        verdict: Literal["collision", "object_collision"] | None = None
        if self.obstacle is not None and self.obstacle.penetrated(q):
            verdict = "object_collision"
        elif self_collides(self.hand, q):
            verdict = "collision"
        self._checked = (key, verdict)
        return verdict

    def penetrations(self, q: NDArray[np.float64], margin_m: float) -> list[Penetration]:
        """Pairs of hand bodies, and links and the obstacle, closer than ``margin_m`` [m]."""
        found = self.hand.penetrations(q, margin_m, near_pairs(self.hand, q, margin_m))
        if self.obstacle is not None:
            found += self.obstacle.penetrations(q, margin_m)
        return found

    def errors(self, state: ContactState) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Per constrained finger, position and centre errors [m]."""
        return (
            np.linalg.norm(state.points[self.rows] - self.points, axis=1),
            np.linalg.norm(state.centres[self.rows] - self.centres, axis=1),
        )

    def errors_at(self, q: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """:meth:`errors` at ``q``, from the compiled tree's contact stack (one native call)."""
        errors = np.empty(2 * len(self.rows))
        compiled_tree(self.hand).errors(q, self.target_stack, self.rows, errors)
        return errors[: len(self.rows)], errors[len(self.rows) :]

    def residual(self, state: ContactState, rows: slice = slice(None)) -> NDArray[np.float64]:
        """``P* - P`` stacked as (p, r) per constrained finger, for the fingers in ``rows``."""
        points, centres = state.points[self.rows], state.centres[self.rows]
        return np.concatenate(
            [self.points[rows] - points[rows], self.centres[rows] - centres[rows]], axis=1
        ).ravel()

    def jacobian(self, jac: Any, rows: slice = slice(None)) -> NDArray[np.float64]:
        """Jacobian of :meth:`residual`'s ``P`` (rows (p_i, r_i) per constrained finger)."""
        return stack_rows(jac.points[self.rows][rows], jac.centres[self.rows][rows])


def stack_rows(
    J_points: NDArray[np.float64], J_centres: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Jacobian rows in the order of :meth:`ContactProblem.residual`: (p_i, r_i) per finger."""
    return np.concatenate([J_points, J_centres], axis=1).reshape(-1, J_points.shape[-1])


def _coupling_weights(hand: Hand) -> NDArray[np.float64]:
    """Per coordinate, how many URDF joints it drives (weighted by multiplier^2): diag(E^T E)."""
    return np.asarray(np.square(expansion_matrix(hand)).sum(axis=0))


def _paper_attempt(
    hand: Hand, problem: ContactProblem, coords: NDArray[np.float64], s: IKSettings
) -> Attempt:
    """Inner loop of Algorithm 1 with ``Comp_Nxt_C`` of Eqs. (7)-(8)."""
    q, psi = hang_from_thumb(hand, coords, problem.target)
    others = slice(1, None)  # the thumb holds by construction (Eq. (3))
    # Column scaling equal to the augmented Jacobian's minimum-norm weighting (module docstring).
    scale = 1.0 / np.sqrt(np.concatenate([[1.0], _coupling_weights(hand)]))
    history = [q.copy()] if s.record_history else None
    previous: ContactState | None = None
    stalled = 0
    for k in range(s.max_iterations + 1):
        jac = hand.contact_jacobians(q)
        state = jac.state
        pos, cen = problem.errors(state)
        if max(pos.max(), cen.max()) < s.d_min_m:  # Step 7, Eq. (9)
            return Attempt(q, "converged", k, max(pos.max(), cen.max()), history)
        if previous is not None:  # Step 13, Eq. (10)
            moved = np.linalg.norm(state.points - previous.points, axis=1).sum()
            moved += np.linalg.norm(state.centres - previous.centres, axis=1).sum()
            stalled = stalled + 1 if moved < s.s_min_m else 0
            if stalled >= s.stall_iterations:
                return Attempt(q, "no_progress", k, max(pos.max(), cen.max()), history)
        if k == s.max_iterations:
            break
        previous = state
        J = _thumb_hanging_jacobian(problem, jac, others)
        step = scale * (np.linalg.pinv(J * scale) @ (s.alpha * problem.residual(state, others)))
        psi += step[0]  # Eq. (8)
        coords = np.clip(coords + step[1:], hand.lower, hand.upper)
        q, _ = hang_from_thumb(hand, coords, problem.target, psi)
        if history is not None:
            history.append(q.copy())
    pos, cen = problem.errors(hand.contact_state(q))
    return Attempt(q, "max_iterations", s.max_iterations, max(pos.max(), cen.max()), history)


def _thumb_hanging_jacobian(
    problem: ContactProblem, jac: Any, others: slice
) -> NDArray[np.float64]:
    """Jacobian of the other fingers' (p, r) w.r.t. ``C' = (psi, coordinates)``.

    The wrist is not free: it moves so that the thumb contact frame stays put except for the
    rotation ``psi`` about the thumb normal. With ``B``/``Q`` the thumb frame's Jacobian columns
    of the wrist twist and of the coordinates, the wrist twist is
    ``v_b = B^-1 ([0; n_T] psi_dot - Q x_dot)``.
    """
    hung = problem.rows[0]
    thumb = np.vstack([jac.points[hung], jac.angular[hung]])  # 6 x nv, world-aligned at p_T
    B, Q = thumb[:, :6], thumb[:, 6:]
    rhs = np.zeros((6, 1 + Q.shape[1]))
    rhs[3:, 0] = jac.state.normals[hung]
    rhs[:, 1:] = -Q
    wrist = np.linalg.solve(B, rhs)  # d(v_b) / d(psi, x)
    J = problem.jacobian(jac, others)
    out = J[:, :6] @ wrist
    out[:, 1:] += J[:, 6:]
    return out


def _lm_attempt(
    hand: Hand, problem: ContactProblem, coords: NDArray[np.float64], s: IKSettings
) -> Attempt:
    """Free-wrist Levenberg-Marquardt from the thumb-hung start, then collision repair."""
    q, _ = hang_from_thumb(hand, coords, problem.target)
    return _lm_from(hand, problem, q, s)


def _lm_from(hand: Hand, problem: ContactProblem, q: NDArray[np.float64], s: IKSettings) -> Attempt:
    """Levenberg-Marquardt from the configuration ``q``, then collision repair."""
    history = [q.copy()] if s.record_history else None
    attempt = _lm_loop(hand, problem, q, s, s.max_iterations, history)
    if attempt.outcome != "converged" or problem.collision(attempt.q) is None:
        return attempt
    q, used = _separate(hand, problem, attempt.q, s, history)
    budget = max(s.max_iterations - attempt.iterations - used, 1)
    refined = _lm_loop(hand, problem, q, s, budget, history)
    return replace(refined, iterations=refined.iterations + attempt.iterations + used)


def _lm_loop(
    hand: Hand,
    problem: ContactProblem,
    q: NDArray[np.float64],
    s: IKSettings,
    max_iterations: int,
    history: list[NDArray[np.float64]] | None,
) -> Attempt:
    """Levenberg-Marquardt on all contacts with a free wrist; bounds as an active set.

    The hot loop of the IK, compiled (``sahgrasp/ik/_lm.c``, docs/methods/ik.md "Compiled loop"):
    from
    the damping 1e-3, each iteration solves ``(J_F^T J_F + mu I) dx = J_F^T e`` on the free
    coordinates ``F`` (a coordinate at a bound that the gradient pushes outwards is fixed),
    integrates, clamps the joints to their limits, and accepts the step if the cost ``|e|^2``
    decreased (``mu / 3``, at least 1e-7), else retries with ``4 mu`` up to 1e4. A start ends
    converged once every contact error is below ``refine_m``, or when its cost has not halved in
    ``stall_iterations`` accepted steps or the damping ran out (converged if every error is
    below ``d_min_m``, else ``no_progress``).
    """
    q = np.array(q, dtype=np.float64)  # the compiled loop updates it in place
    code, iterations, error = compiled_tree(hand).solve(
        q,
        problem.target_stack,
        problem.rows,
        max_iterations,
        s.refine_m,
        s.d_min_m,
        s.stall_iterations,
        None if history is None else _recorder(history, q),
    )
    return Attempt(q, OUTCOMES[code], iterations, error, history)


def _recorder(history: list[NDArray[np.float64]], q: NDArray[np.float64]) -> Callable[[], None]:
    """A callback that appends a copy of ``q`` (which the compiled loop updates) to ``history``."""
    return lambda: history.append(q.copy())


REPAIR_PATIENCE = 3
"""With an obstacle: repair steps without a new low of the summed or deepest penetration."""


def _separate(
    hand: Hand,
    problem: ContactProblem,
    q: NDArray[np.float64],
    s: IKSettings,
    history: list[NDArray[np.float64]] | None,
) -> tuple[NDArray[np.float64], int]:
    """Push colliding bodies apart along coal's normals while holding the contacts.

    The solution set is redundant (27 DoF, 20 contact constraints for the SAH), so a converged but
    colliding configuration can usually slide along it out of collision: each step solves the
    contact rows together with one row per penetrating pair asking the second body to move along
    the separating normal by the penetration depth plus a margin (damped least squares, bounds as
    an active set; compiled, ``Tree.repair``). A link in the obstacle is such a
    pair whose first body is the object (fixed). With an obstacle, a repair whose summed and
    deepest penetration set no new low for :data:`REPAIR_PATIENCE` steps is given up: such
    repairs rarely end clear, and each step costs a hand-object query (docs/methods/ik.md, item 5).
    """
    # Only with an obstacle: without one, giving up early saved no time and cost starts.
    patience = REPAIR_PATIENCE if problem.obstacle is not None else s.repair_iterations
    lows_m, stalled = np.array([np.inf, np.inf]), 0
    tree, out = compiled_tree(hand), np.empty(hand.nq)
    for k in range(s.repair_iterations):
        penetrations = problem.penetrations(q, s.collision_margin_m)
        if not penetrations:
            return q, k
        depths = np.array([p.depth_m for p in penetrations])
        # A hopeless repair wanders: give it up once neither the summed nor the deepest
        # penetration has set a new low for ``patience`` steps (the deepest alone cut the
        # three-finger can's paper grasp, whose repair climbs for three steps and then clears).
        depth_m = np.array([depths.sum(), depths.max()])
        stalled = 0 if np.any(depth_m < lows_m) else stalled + 1
        lows_m = np.minimum(lows_m, depth_m)
        if stalled >= patience:
            return q, k
        # The compiled step (sahgrasp/ik/_lm.c) numbers joints as its tree (the object: its world).
        joints = np.array(
            [(tree_joint(p.joint_a), tree_joint(p.joint_b)) for p in penetrations], dtype=np.int64
        )
        points = np.array([(p.point_a, p.point_b) for p in penetrations])
        normals = np.array([p.normal for p in penetrations])
        args = (problem.target_stack, problem.rows, joints, points, normals, depths, out)
        if not tree.repair(q, *args):  # the rows are degenerate: no separating step exists here
            return q, k
        q = out.copy()
        if history is not None:
            history.append(q.copy())
    return q, s.repair_iterations


AttemptFn = Callable[[Hand, "ContactProblem", NDArray[np.float64], IKSettings], Attempt]
"""One inner solve: from the initial coordinates (or configuration) of one start to an
:class:`Attempt`."""


@dataclass(frozen=True)
class InnerSolver:
    """An inner solver of Algorithm 1: how one start becomes an :class:`Attempt`.

    Starts come as finger coordinates (a sequence's or random initial pose) or as whole
    configurations, wrist included (the learned starts of a grasp database). A solver that can
    use a whole configuration as it is says so with ``from_configuration``; any other receives
    the configuration's finger coordinates and hangs the hand from the thumb (Eq. (3)) as it does
    for every start.

    Attributes:
        from_coordinates: The attempt from finger coordinates.
        from_configuration: The attempt from a whole configuration, or None (see above).
    """

    from_coordinates: AttemptFn
    from_configuration: AttemptFn | None = None

    def attempt(
        self,
        hand: Hand,
        problem: ContactProblem,
        kind: Literal["q", "coords"],
        x: NDArray[np.float64],
        s: IKSettings,
    ) -> Attempt:
        """The attempt from start ``x``: a configuration (``kind == "q"``) or coordinates."""
        if kind == "q" and self.from_configuration is not None:
            return self.from_configuration(hand, problem, x, s)
        coords = x if kind == "coords" else hand.finger_part(x)
        return self.from_coordinates(hand, problem, coords, s)


INNER_SOLVERS: dict[Method, InnerSolver] = {
    "auto": InnerSolver(_lm_attempt, _lm_from),
    "paper": InnerSolver(_paper_attempt),
}
"""The inner solver of each :attr:`IKSettings.method`."""


def solve_ik(
    hand: Hand,
    target: GraspTarget,
    settings: IKSettings | None = None,
    sequence: Sequence | None = None,
    free_fingers: tuple[str, ...] = (),
    obstacle: GraspObject | None = None,
    database: GraspDatabase | None = None,
    **overrides: Any,
) -> IKResult:
    """Find wrist pose and joints that put every fingertip on its contact (Algorithm 1).

    Args:
        hand: The hand model.
        target: One contact per finger that touches the object: at least two, the thumb
            among them when the hand has one; the fingers without a contact are free, placed
            clear of the object and of the other links.
        settings: Solver parameters (defaults: :class:`IKSettings`).
        sequence: Initial-pose sequence (default: the hand's shipped or Table-1 sequence).
        free_fingers: Fingers left without a contact, named explicitly (optional: every finger
            without a contact in ``target`` is free).
        obstacle: The object being grasped, placed in the world: a solution must not put any
            link into it, except each contact fingertip sphere up to ``d_min`` (docs/methods/ik.md).
            Its collision pieces are built once per (hand, object) and kept for the next solves.
        database: Grasp database of ``init="learned"`` (default: the hand's shipped one; the
            sequence alone if it has none).
        **overrides: Fields of :class:`IKSettings` to change, e.g. ``method="paper"``.

    Returns:
        The result; an unreachable target gives ``success=False`` with a reason, not an error
        (``object_collision`` when the contacts were reached only through the obstacle).

    Raises:
        InvalidTargetError: Unknown or repeated fingers, fewer than two contacts, no thumb
            contact, a free finger with a contact (NaN and non-unit normals are
            refused when the target is built); an obstacle that is not a GraspObject.
        SequenceFileError: ``sequence`` was made for another hand (``database``: a
            :class:`~sahgrasp.ik.learned.GraspDatabaseError`).
        InvalidSettingsError: ``settings`` is not an :class:`IKSettings`, an override is not one
            of its fields or out of its range, or another argument has the wrong type.
    """
    s = _checked_settings(settings)
    if overrides:  # replace() validates the settings again: about 8 us a solve
        s = replace(s, **_checked_overrides(overrides))
    inner = INNER_SOLVERS[s.method]
    return run_algorithm1(hand, target, inner, s, sequence, free_fingers, obstacle, database)


def run_algorithm1(
    hand: Hand,
    target: GraspTarget,
    inner: InnerSolver | AttemptFn,
    settings: IKSettings,
    sequence: Sequence | None = None,
    free_fingers: tuple[str, ...] = (),
    obstacle: GraspObject | None = None,
    database: GraspDatabase | None = None,
) -> IKResult:
    """The outer loop of Algorithm 1 around any inner solver.

    ``inner`` is an :class:`InnerSolver` (those of the methods: :data:`INNER_SOLVERS`) or an
    :data:`AttemptFn` alone, which then starts from finger coordinates only. The other arguments
    are those of :func:`solve_ik`.
    """
    free_fingers = _check_arguments(hand, target, settings, sequence, free_fingers, database)
    solver = inner if isinstance(inner, InnerSolver) else InnerSolver(inner)
    # The shipped sequence and database are loaded once per hand, on first use: not timed.
    sequence = sequence or default_sequence(hand)
    if settings.init == "learned":
        database = database or default_database(hand)
    start = time.perf_counter()  # the whole solve: the problem's set-up and the result too
    problem = ContactProblem(hand, target, free_fingers, obstacle, settings.d_min_m)
    free_fingers = problem.free_fingers  # the given ones and every finger without a contact
    sequence.check_hand(hand)
    if settings.init == "learned" and database is not None:
        database.check_hand(hand)
    attempts: list[Attempt] = []
    for kind, x in _starts(hand, problem, settings, sequence, database):
        attempt = solver.attempt(hand, problem, kind, x, settings)
        attempt = _checked(problem, attempt, free_fingers)
        attempt = replace(attempt, seconds=time.perf_counter() - start)
        attempts.append(attempt)
        if attempt.outcome == "converged":
            return _result(hand, problem, attempt, attempts, True, start)
    best = min(attempts, key=lambda a: a.error_m)
    return _result(hand, problem, best, attempts, False, start)


def _checked_settings(settings: object) -> IKSettings:
    if settings is None:
        return IKSettings()
    if not isinstance(settings, IKSettings):
        raise InvalidSettingsError(
            f"settings must be an IKSettings (or None: the defaults), got {type(settings).__name__}"
        )
    return settings


_SETTING_NAMES = frozenset(IKSettings.__dataclass_fields__)


def _checked_overrides(overrides: dict[str, Any]) -> dict[str, Any]:
    unknown = sorted(set(overrides) - _SETTING_NAMES)
    if unknown:
        raise InvalidSettingsError(
            f"unknown IK setting(s) {unknown}; valid: {sorted(_SETTING_NAMES)}"
        )
    return overrides


def _check_arguments(
    hand: object,
    target: object,
    settings: object,
    sequence: object,
    free_fingers: object,
    database: object,
) -> tuple[str, ...]:
    """Refuse arguments of the wrong type with a typed error; the free fingers as a tuple.

    The values themselves (fingers, contacts, a sequence's hand) are checked where they are used.
    """
    if not isinstance(hand, Hand):
        raise InvalidSettingsError(
            f"hand must be a Hand (sahgrasp.load_hand({DEFAULT_HAND!r})), got {type(hand).__name__}"
        )
    if not isinstance(target, GraspTarget):
        raise InvalidTargetError(
            f"target must be a GraspTarget (one ContactTarget per finger), got "
            f"{type(target).__name__}"
        )
    _checked_settings(settings)
    for name, value, kind in (
        ("sequence", sequence, Sequence),
        ("database", database, GraspDatabase),
    ):
        if value is not None and not isinstance(value, kind):
            raise InvalidSettingsError(
                f"{name} must be a {kind.__name__} or None (the hand's shipped one), got "
                f"{type(value).__name__}"
            )
    if isinstance(free_fingers, str) or not isinstance(free_fingers, tuple | list):
        raise InvalidTargetError(
            f"free_fingers must be a tuple of finger names, e.g. ('ring',), got {free_fingers!r}"
        )
    if not all(isinstance(f, str) for f in free_fingers):
        raise InvalidTargetError(f"free_fingers must hold finger names, got {free_fingers!r}")
    return tuple(free_fingers)


def _checked(problem: ContactProblem, attempt: Attempt, free_fingers: tuple[str, ...]) -> Attempt:
    """``attempt`` after Step 8: a converged ``q`` that collides is refused, free fingers placed."""
    if attempt.outcome != "converged":
        return attempt
    rejected = problem.collision(attempt.q)
    if rejected is not None:
        return replace(attempt, outcome=rejected)
    if free_fingers:
        return replace(attempt, q=_place_free_fingers(problem, attempt.q, free_fingers))
    return attempt


def _place_free_fingers(
    problem: ContactProblem, q: NDArray[np.float64], free_fingers: tuple[str, ...]
) -> NDArray[np.float64]:
    """``q`` with the fingers without a contact moved clear of the object and the other links.

    Only the free fingers' joints move (``HandObjectClearance.place_free_fingers``), so the
    contacts are untouched; a placement that would collide is not taken.
    """
    # One checker per (hand, object), not one per solve (about 0.7 ms to build without an object).
    checker = (
        checker_of(problem.hand, None) if problem.obstacle is None else problem.obstacle.checker
    )
    placed = checker.place_free_fingers(q, free_fingers).q
    return placed if problem.collision(placed) is None else q


def _starts(
    hand: Hand,
    problem: ContactProblem,
    s: IKSettings,
    sequence: Sequence,
    database: GraspDatabase | None,
) -> Iterator[tuple[Literal["q", "coords"], NDArray[np.float64]]]:
    """The ``max_inits`` starts: learned configurations first, then the sequence's coordinates."""
    used = 0
    # Database keys hold every finger: a problem with free fingers starts from the sequence.
    if s.init == "learned" and database is not None and len(problem.fingers) == len(hand.fingers):
        key = contact_key(problem.points, problem.normals)
        count = min(s.learned_starts, s.max_inits)
        for q in database.starts(hand, key, problem.target_stack, count):
            used += 1
            yield "q", q
    init = "sequence" if s.init == "learned" else s.init
    rest = s.max_inits - used
    for lambdas in initial_lambdas(init, rest, s.seed, sequence, problem.target):
        yield "coords", sequence.basis.coordinates(hand, lambdas)


_FAILURE_REASONS: dict[str, Reason] = {
    "max_iterations": "max_inits",
    "no_progress": "no_progress",
    "collision": "collision",
    "object_collision": "object_collision",
}
"""The failure reason of a solve whose best start ended with this :attr:`Attempt.outcome`."""


def _result(
    hand: Hand,
    problem: ContactProblem,
    chosen: Attempt,
    attempts: list[Attempt],
    success: bool,
    start: float,
) -> IKResult:
    pos, cen = problem.errors_at(chosen.q)
    reason: Reason
    if success:
        reason, collision_free = "converged", True
    else:
        collision_free = not self_collides(hand, chosen.q)
        # An inner solver given by the caller may name other outcomes: out of starts.
        reason = _FAILURE_REASONS.get(chosen.outcome, "max_inits")
    clearance = problem.obstacle.clearance(chosen.q) if problem.obstacle is not None else None
    seconds = time.perf_counter() - start  # the final clearance is part of the solve's time
    return IKResult(
        name=problem.target.name,
        success=success,
        reason=reason,
        q=chosen.q,
        position_errors_m=pos,
        centre_errors_m=cen,
        inits_used=len(attempts),
        iterations=sum(a.iterations for a in attempts),
        time_s=seconds,
        collision_free=collision_free,
        fingers=problem.fingers,
        attempts=tuple(a.outcome for a in attempts),
        attempt_seconds=tuple(a.seconds for a in attempts),
        history=tuple(chosen.history) if chosen.history is not None else None,
        object_clearance_m=clearance.distance_m if clearance is not None else None,
        closest_link=clearance.link if clearance is not None else None,
    )
