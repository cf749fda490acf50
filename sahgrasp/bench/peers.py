"""Peer inner solvers for ``sahgrasp bench ik``: the tools a user would otherwise reach for.

Each peer replaces only the inner loop of Algorithm 1: it starts from the same initial
configuration (the thumb-hung pose of the same sequence), solves the same residual (contact points
and sphere centres of every finger, free wrist), and its result goes through the same acceptance
test (Eq. (9), limits, self-collision) in :func:`sahgrasp.ik.solver.run_algorithm1`.

* ``scipy`` -- ``scipy.optimize.least_squares`` (``method="trf"``, joint bounds, analytic
  Jacobian through Pinocchio's ``dIntegrate``);
* ``pink`` -- differential IK with a joint-limit QP (pin-pink, quadprog), iterated to convergence.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import NDArray
from scipy.optimize import least_squares

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.extras import install_command
from sahgrasp.ik.initial import hang_from_thumb
from sahgrasp.ik.solver import Attempt, ContactProblem, IKSettings, InnerSolver
from sahgrasp.model.hand import Hand

__all__ = ["BENCH_EXTRA", "PEERS", "PEER_MODULES", "available_peers", "pink_attempt",
           "scipy_attempt"]  # fmt: skip

BENCH_EXTRA = 'pip install "sahgrasp[bench]"'
"""How to install the optional peers (the ``bench`` extra of the package) from the package index;
messages say :func:`sahgrasp.core.extras.install_command`, which fits an editable install too."""


def _finish(
    hand: Hand, problem: ContactProblem, q: NDArray[np.float64], iterations: int, s: IKSettings
) -> Attempt:
    pos, cen = problem.errors(hand.contact_state(q))
    error = float(max(pos.max(), cen.max()))
    outcome = "converged" if error < s.d_min_m else "no_progress"
    return Attempt(q, outcome, iterations, error, None)


def scipy_attempt(
    hand: Hand, problem: ContactProblem, coords: NDArray[np.float64], s: IKSettings
) -> Attempt:
    """Bounded trust-region least squares on the contact residual, from the thumb-hung start."""
    q0, _ = hang_from_thumb(hand, coords, problem.target)
    x0 = np.zeros(hand.nv)
    joints = hand.finger_part(q0)
    lower = np.concatenate([np.full(6, -np.inf), hand.lower - joints])
    upper = np.concatenate([np.full(6, np.inf), hand.upper - joints])
    x0 = np.clip(x0, lower, upper)

    def configuration(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return hand.integrate(q0, x)

    def fun(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return -problem.residual(hand.contact_state(configuration(x)))

    def jac(x: NDArray[np.float64]) -> NDArray[np.float64]:
        J = problem.jacobian(hand.contact_jacobians(configuration(x)))
        return J @ pin.dIntegrate(hand.model, q0, x, pin.ArgumentPosition.ARG1)

    fit = least_squares(
        fun, x0, jac=jac, bounds=(lower, upper), method="trf",
        xtol=1e-12, ftol=1e-14, gtol=1e-12, max_nfev=s.max_iterations,
    )  # fmt: skip
    return _finish(hand, problem, configuration(fit.x), int(fit.njev or fit.nfev), s)


def pink_attempt(
    hand: Hand, problem: ContactProblem, coords: NDArray[np.float64], s: IKSettings
) -> Attempt:
    """Pink's QP differential IK: position tasks on every contact point and sphere centre."""
    import pink  # optional dependency (extra "bench")
    from pink.tasks import FrameTask

    q, _ = hang_from_thumb(hand, coords, problem.target)
    configuration = pink.Configuration(hand.model, hand.model.createData(), q)
    tasks = []
    for i, finger in enumerate(problem.fingers):
        tip_link = hand.description.fingers[hand.fingers.index(finger)].tip_link
        for frame, point in (
            (f"{finger}_contact", problem.points[i]),
            (tip_link, problem.centres[i]),
        ):
            task = FrameTask(frame, position_cost=1.0, orientation_cost=0.0)
            task.set_target(pin.SE3(np.eye(3), point))
            tasks.append(task)
    dt = 1.0
    for k in range(s.max_iterations):
        pos, cen = problem.errors(hand.contact_state(configuration.q))
        if max(pos.max(), cen.max()) < s.refine_m:
            return _finish(hand, problem, configuration.q, k, s)
        velocity = pink.solve_ik(configuration, tasks, dt, solver="quadprog", damping=1e-9)
        configuration.integrate_inplace(velocity, dt)
    return _finish(hand, problem, configuration.q, s.max_iterations, s)


PEERS: dict[str, InnerSolver] = {
    "scipy": InnerSolver(scipy_attempt),
    "pink": InnerSolver(pink_attempt),
}
"""Peer name -> inner solver (from finger coordinates only: learned starts are not compared)."""

PEER_MODULES: dict[str, tuple[str, ...]] = {
    "scipy": ("scipy.optimize",),
    "pink": ("pink", "qpsolvers", "quadprog"),
}
"""Peer name -> the modules it imports (pink's QP goes through qpsolvers to quadprog)."""


def _missing_module(modules: Sequence[str]) -> str | None:
    """The first of ``modules`` that cannot be imported, or None."""
    for module in modules:
        try:
            importlib.import_module(module)
        except ImportError:
            return module
    return None


def available_peers(names: Sequence[str]) -> tuple[list[str], dict[str, str]]:
    """Split peer names into those that can run and those skipped, with the reason why.

    Raises:
        InvalidSettingsError: A name is not one of :data:`PEERS`.
    """
    unknown = [name for name in names if name not in PEERS]
    if unknown:
        raise InvalidSettingsError(f"unknown peer(s) {unknown}; valid: {', '.join(PEERS)}")
    ready: list[str] = []
    skipped: dict[str, str] = {}
    for name in dict.fromkeys(names):  # each once, in order
        missing = _missing_module(PEER_MODULES[name])
        if missing is None:
            ready.append(name)
        else:
            hint = install_command("bench")
            skipped[name] = f"module {missing!r} is not installed; install it with {hint}"
    return ready, skipped
