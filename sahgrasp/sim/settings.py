"""Settings of the physics hold test: the model's parameters and the hold criterion."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.quality.weight import PULL_DIRECTIONS

__all__ = [
    "DEXGRASPBENCH_MASS_KG",
    "DIRECTIONS",
    "LIGHT_SQUEEZE_N",
    "HoldSettings",
    "dexgraspbench_solver",
    "soft_friction",
]

DIRECTIONS: tuple[tuple[str, tuple[float, float, float]], ...] = PULL_DIRECTIONS
"""The six pulls of the test, world axes (DexGraspNet's and BODex's six directions): those the
weight support (:mod:`sahgrasp.quality.weight`) resists, one table for both."""

LIGHT_SQUEEZE_N = 1.0
"""The light squeeze [N] per contact finger on average, which separates strong grasps from weak."""

DEXGRASPBENCH_MASS_KG = 0.1
"""The mass [kg] DexGraspBench gives every object (its ``obj_mass``): the field's convention."""


@dataclass(frozen=True)
class HoldSettings:
    """Parameters of the hold test (docs/methods/physics.md gives the reason for each default).

    Attributes:
        friction: Coulomb friction coefficient of every hand-object contact.
        patch_radius_m: Radius [m] of a fingertip's contact patch (soft-finger contacts: a
            moment up to ``2/3 * friction * patch_radius_m`` times the normal force resists
            turning about the normal, the torsional friction of a uniformly pressed disk);
            0: hard-finger point contacts.
        density_kg_m3: Object density [kg/m^3], used when ``mass_kg`` is None.
        mass_kg: Object mass [kg]; None: from ``density_kg_m3`` and the pieces' volume.
        squeeze_n: Mean normal force [N] each contact finger presses with while settling.
        settle_s: Simulated time [s] of the squeeze before the pulls.
        pull_s: Simulated time [s] each pull of mass x 9.81 N lasts.
        gravity_m_s2: Acceleration [m/s^2] the pull's force equals per kilogram.
        max_displacement_m: The grasp holds if the object's centre of mass moves less [m]...
        max_rotation_deg: ...and the object turns less [deg], in every direction.
        bodex_displacement_m: BODex's displacement threshold [m] (its verdict is reported too).
        bodex_rotation_deg: BODex's rotation threshold [deg].
        contact_distance_m: A fingertip nearer the object than this [m] is a contact finger.
        stiffness_nm_rad: Position-servo gain of every actuated joint [N m/rad].
        damping_nms_rad: Servo damping [N m s/rad] (velocity feedback).
        armature_kg_m2: Reflected rotor inertia of every hand joint [kg m^2].
        timestep_s: Simulation time step [s] (5 ms: a 10 ms step lets a 9 g fork spin under
            its squeeze, docs/methods/physics.md "Which MuJoCo settings").
        contact_timeconst_s: Time constant [s] of MuJoCo's soft contacts (``solref``; at least
            twice ``timestep_s``, MuJoCo's floor).
        contact_impedance: MuJoCo's contact impedance beyond 1 mm of penetration (``solimp``
            dmax, in (0, 1): nearer 1, less penetration under a force).
        solver_iterations: Newton iterations of MuJoCo's constraint solver per step.
        ls_iterations: Line-search iterations per Newton iteration (MuJoCo's default, 50: with
            friction stiffer than the normal, ``impratio`` > 1, fewer leave the solver short
            of convergence and the contacts chatter).
        noslip_iterations: Iterations of MuJoCo's no-slip post-solver (2, DexGraspBench's:
            a contact loaded inside its friction cone sticks, as Coulomb's law has it; 0
            lets MuJoCo's soft friction creep, :func:`soft_friction`).
        impratio: Ratio of the friction to the normal constraint impedance (MuJoCo; 10,
            DexGraspBench's: friction ten times stiffer than the normal).
        balance_friction: Share of ``friction`` the squeeze may use to balance its forces.
        directions: The pulls to run, a subset of :data:`DIRECTIONS`' labels (all six by
            default; the grasp holds only if it holds in all six).
        stop_at_first_failure: Stop at the first direction that fails (the others unreported).
        stop_at_rest: End a pull early once the object has come to rest (moving slower than
            1 mm/s and turning slower than 1 deg/s over the last 0.1 s, at least 0.2 s into
            the pull) and even at that speed until the end of the pull it would stay below
            half of both thresholds; False: every pull lasts ``pull_s``.
    """

    friction: float = 0.6
    patch_radius_m: float = 0.0025
    density_kg_m3: float = 1000.0
    mass_kg: float | None = None
    squeeze_n: float = 10.0
    settle_s: float = 0.3
    pull_s: float = 1.0
    gravity_m_s2: float = 9.81
    max_displacement_m: float = 0.020
    max_rotation_deg: float = 15.0
    bodex_displacement_m: float = 0.050
    bodex_rotation_deg: float = 15.0
    contact_distance_m: float = 0.003
    stiffness_nm_rad: float = 10.0
    damping_nms_rad: float = 0.3
    armature_kg_m2: float = 0.005
    timestep_s: float = 0.005
    contact_timeconst_s: float = 0.01
    contact_impedance: float = 0.99
    solver_iterations: int = 20
    ls_iterations: int = 50
    noslip_iterations: int = 2
    impratio: float = 10.0
    balance_friction: float = 0.5
    directions: tuple[str, ...] = tuple(label for label, _ in DIRECTIONS)
    stop_at_first_failure: bool = False
    stop_at_rest: bool = True

    def __post_init__(self) -> None:
        nonnegative = {
            "friction": self.friction,
            "patch_radius_m": self.patch_radius_m,
            "settle_s": self.settle_s,
        }
        positive = {
            "density_kg_m3": self.density_kg_m3,
            "squeeze_n": self.squeeze_n,
            "pull_s": self.pull_s,
            "gravity_m_s2": self.gravity_m_s2,
            "max_displacement_m": self.max_displacement_m,
            "max_rotation_deg": self.max_rotation_deg,
            "bodex_displacement_m": self.bodex_displacement_m,
            "bodex_rotation_deg": self.bodex_rotation_deg,
            "contact_distance_m": self.contact_distance_m,
            "stiffness_nm_rad": self.stiffness_nm_rad,
            "damping_nms_rad": self.damping_nms_rad,
            "armature_kg_m2": self.armature_kg_m2,
            "timestep_s": self.timestep_s,
            "contact_timeconst_s": self.contact_timeconst_s,
            "impratio": self.impratio,
        }
        if self.mass_kg is not None:
            positive["mass_kg"] = self.mass_kg
        for name, value in {**nonnegative, **positive}.items():
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise InvalidSettingsError(f"hold setting {name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0 or (name in positive and value == 0):
                kind = "positive" if name in positive else "non-negative"
                raise InvalidSettingsError(
                    f"hold setting {name} must be a finite {kind} number, got {value!r}"
                )
        if not 0.0 <= self.balance_friction <= 1.0:
            raise InvalidSettingsError(
                f"hold setting balance_friction must be in [0, 1], got {self.balance_friction!r}"
            )
        if self.timestep_s > 0.01:
            raise InvalidSettingsError(
                f"hold setting timestep_s must be at most 0.01 s (contacts stay stable), got "
                f"{self.timestep_s!r}"
            )
        if not 0.0 < self.contact_impedance < 1.0:
            raise InvalidSettingsError(
                f"hold setting contact_impedance must be in (0, 1), got {self.contact_impedance!r}"
            )
        if not self.contact_timeconst_s >= 2.0 * self.timestep_s:
            raise InvalidSettingsError(
                f"hold setting contact_timeconst_s must be at least twice timestep_s "
                f"({2.0 * self.timestep_s!r} s), got {self.contact_timeconst_s!r}"
            )
        if self.settle_s + self.pull_s > 60.0:
            raise InvalidSettingsError("hold settings settle_s + pull_s must be at most 60 s")
        labels = [label for label, _ in DIRECTIONS]
        if (
            not isinstance(self.directions, tuple)
            or not self.directions
            or any(d not in labels for d in self.directions)
            or len(set(self.directions)) != len(self.directions)
        ):
            raise InvalidSettingsError(
                f"hold setting directions must be distinct labels among {labels}, "
                f"got {self.directions!r}"
            )
        for name, flag in (("stop_at_first_failure", self.stop_at_first_failure),
                           ("stop_at_rest", self.stop_at_rest)):  # fmt: skip
            if not isinstance(flag, bool):
                raise InvalidSettingsError(
                    f"hold setting {name} must be True or False, got {flag!r}"
                )
        noslip = self.noslip_iterations
        if isinstance(noslip, bool) or not isinstance(noslip, int) or not 0 <= noslip <= 1000:
            raise InvalidSettingsError(
                f"hold setting noslip_iterations must be an integer in [0, 1000], got {noslip!r}"
            )
        for name, iterations in (("solver_iterations", self.solver_iterations),
                                 ("ls_iterations", self.ls_iterations)):  # fmt: skip
            if (
                isinstance(iterations, bool)
                or not isinstance(iterations, int)
                or not 1 <= iterations <= 1000
            ):
                raise InvalidSettingsError(
                    f"hold setting {name} must be an integer in [1, 1000], got {iterations!r}"
                )


def dexgraspbench_solver(settings: HoldSettings | None = None) -> HoldSettings:
    """``settings`` (default: :class:`HoldSettings`) in DexGraspBench's MuJoCo solver settings.

    The cross-check of the hold test: DexGraspBench (Chen, Ke, Wang, BODex, ICRA 2025, its
    benchmark ``MjHO``) simulates with a 4 ms time step, the implicitfast integrator,
    elliptic cones, ``impratio`` 10 (friction ten times stiffer than the normal), 2 no-slip
    iterations and MuJoCo's solver defaults (Newton, 100 iterations, 50 line-search
    iterations); its hand contacts' time constant, 5 ms, is below MuJoCo's floor of two time
    steps, which MuJoCo raises it to (8 ms). Every pull lasts its full ``pull_s`` (no end at
    rest). Everything else is kept from ``settings``: the squeeze, the friction and the
    patch's torsional friction (DexGraspBench's 0.02 m torsional coefficient resists turning
    twenty times more), the mass and the pull of its whole weight, the thresholds and the
    pulls' duration -- all as strict as this check's, so a grasp that holds here and not
    there fails for the step, the solver's iterations or the end at rest alone.
    """
    return dataclasses.replace(
        settings or HoldSettings(), timestep_s=0.004, contact_timeconst_s=0.008, impratio=10.0,
        noslip_iterations=2, solver_iterations=100, ls_iterations=50, stop_at_rest=False,
    )  # fmt: skip


def soft_friction(settings: HoldSettings | None = None) -> HoldSettings:
    """``settings`` (default: :class:`HoldSettings`) with MuJoCo's soft, creeping friction.

    The strictest set-up in use: friction as soft as the normal (``impratio`` 1), no no-slip
    post-solver (MuJoCo's own defaults), a 10 ms step with a 20 ms contact time constant. A
    contact loaded inside its friction cone then creeps slowly (a pinch loaded at three
    quarters of its friction limit slides about 6 mm per second), so a grasp that holds here
    holds for its whole pull however its contacts would creep; a light object such as the
    9 g fork spins under the 10 ms step. Reported beside the default by ``sahgrasp bench plan``.
    """
    return dataclasses.replace(
        settings or HoldSettings(), timestep_s=0.01, contact_timeconst_s=0.02, impratio=1.0,
        noslip_iterations=0,
    )  # fmt: skip
