"""The hold test as the planner's extra check: keep the grasps that hold, rank them by margin.

:class:`PhysicsCheck` is a :data:`~sahgrasp.planner.plan.GraspCheck`: called on a planned grasp,
it hold-tests it (:class:`~sahgrasp.sim.hold.HoldTester`, one compiled model per object) and
returns None when the grasp does not hold (the planner drops it) or its hold margin (the planner
ranks the grasps that hold by it, highest first). The margin is how far the worst motion stays
below the test's thresholds, so the grasps ranked first are those least near failing: a grasp
that holds in this simulation by a wide margin also holds where the model differs a little (an
independent simulator, a real hand).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sahgrasp.model.hand import Hand
from sahgrasp.objects import GraspObject
from sahgrasp.sim.hold import HoldResult, HoldTester
from sahgrasp.sim.settings import HoldSettings

__all__ = ["PhysicsCheck", "PhysicsCheckFactory", "hold_margin", "hold_rates", "hold_verdict"]


def hold_margin(result: HoldResult, settings: HoldSettings) -> float:
    """How far the object's worst motion stays below the thresholds, in (-inf, 1].

    ``1 - max(d / d_max, a / a_max)`` over the settling and every pull (displacement ``d`` [m],
    rotation ``a`` [deg], thresholds ``max_displacement_m`` and ``max_rotation_deg``): 1 when the
    object does not move at all, 0 at a threshold, negative past it (a grasp that does not hold).
    A grasp without a pull (no contact, diverged) gets -1.
    """
    if not result.directions:
        return -1.0
    worst = max(
        max(m / settings.max_displacement_m, a / settings.max_rotation_deg)
        for m, a in [
            (result.settle_displacement_m, result.settle_rotation_deg),
            *((d.displacement_m, d.rotation_deg) for d in result.directions),
        ]
    )
    return 1.0 - worst


def hold_verdict(result: HoldResult, settings: HoldSettings) -> dict[str, Any]:
    """The hold test's verdict as a planned grasp's JSON holds it (docs/methods/physics.md, SI)."""
    worst = max(result.directions, key=lambda d: d.displacement_m, default=None)
    turned = max(result.directions, key=lambda d: d.rotation_deg, default=None)
    return {
        "holds": result.holds,
        "holds_bodex": result.holds_bodex,
        "reason": result.reason,
        "detail": result.detail,
        "margin": hold_margin(result, settings),
        "max_displacement_m": None if worst is None else worst.displacement_m,
        "max_rotation_deg": None if turned is None else turned.rotation_deg,
        "squeeze_n": settings.squeeze_n,
        "friction": settings.friction,
        "mass_kg": result.mass_kg,
        "contact_fingers": list(result.contact_fingers),
    }


class PhysicsCheck:
    """The planner's extra check by the hold test (module docstring).

    Args:
        hand: The hand.
        obj: The object at its placement in the world (the one planned).
        settings: The hold test's parameters.

    Attributes:
        verdicts: Per grasp checked (by its seed), its :func:`hold_verdict`.
        results: Per grasp checked (by its seed), its :class:`HoldResult`.
    """

    def __init__(self, hand: Hand, obj: GraspObject, settings: HoldSettings | None = None) -> None:
        self.settings = settings or HoldSettings()
        self.tester = HoldTester(hand, obj, self.settings)
        self.results: dict[int, HoldResult] = {}
        self.verdicts: dict[int, dict[str, Any]] = {}

    def __call__(self, grasp: Any) -> float | None:
        """Hold-test a :class:`~sahgrasp.planner.PlannedGrasp`: None or its margin."""
        result = self.tester.test(grasp.q, name=str(grasp.seed), fingers=tuple(grasp.fingers))
        self.results[grasp.seed] = result
        self.verdicts[grasp.seed] = hold_verdict(result, self.settings)
        return hold_margin(result, self.settings) if result.holds else None

    @property
    def checked(self) -> int:
        """Grasps hold-tested so far."""
        return len(self.results)

    def annotate(self, document: dict[str, Any]) -> dict[str, Any]:
        """Add each grasp's ``hold`` verdict to a plan's JSON document (matched by seed)."""
        for entry in document.get("grasps", []):
            verdict = self.verdicts.get(entry.get("seed"))
            if verdict is not None:
                entry["hold"] = verdict
        held = [v for v in self.verdicts.values()]
        document.setdefault("summary", {})["hold_checked"] = len(held)
        document["summary"]["hold_passed"] = sum(v["holds"] for v in held)
        return document


@dataclass(frozen=True)
class PhysicsCheckFactory:
    """Builds a :class:`PhysicsCheck` for a hand and an object.

    Picklable, so that a folder run's workers build their own
    (``sahgrasp.planner.folder.plan_file(make_check=)``).

    Attributes:
        settings: The hold test's parameters.
    """

    settings: HoldSettings

    def __call__(self, hand: Hand, obj: GraspObject) -> PhysicsCheck:
        """The check of ``hand``'s grasps of ``obj``."""
        return PhysicsCheck(hand, obj, self.settings)


def hold_rates(
    hand: Hand,
    obj: GraspObject,
    qs: list[Any],
    settings: dict[str, HoldSettings],
    fingers: list[tuple[str, ...] | None] | None = None,
) -> dict[str, dict[str, Any]]:
    """Hold-test configurations ``qs`` of ``obj`` under each named settings.

    ``fingers``: per configuration its contact fingers (a planned grasp's), or None for all
    fingertips near the object (:meth:`HoldTester.test`).

    Returns, per name: ``checked``, ``holds``, ``hold_rate`` (None without grasps),
    ``holds_bodex``, the ``reasons`` of the failures counted, ``held`` (each grasp's verdict,
    in the order of ``qs``), ``checks_per_cpu_s`` (hold tests per CPU second of this
    process, the models' compilation excluded) and ``mass_kg`` (the object's, in that test).
    """
    import time
    from collections import Counter

    out: dict[str, dict[str, Any]] = {}
    for label, s in settings.items():
        tester = HoldTester(hand, obj, s)
        cpu = time.process_time()
        named = fingers if fingers is not None else [None] * len(qs)
        results = [tester.test(q, fingers=f) for q, f in zip(qs, named, strict=True)]
        cpu_s = time.process_time() - cpu
        holds = sum(r.holds for r in results)
        out[label] = {
            "checked": len(results),
            "holds": holds,
            "hold_rate": holds / len(results) if results else None,
            "holds_bodex": sum(r.holds_bodex for r in results),
            "reasons": dict(sorted(Counter(r.reason for r in results if not r.holds).items())),
            "held": [r.holds for r in results],
            "checks_per_cpu_s": len(results) / cpu_s if results and cpu_s > 0 else None,
            "mass_kg": tester.sim.mass_kg,
        }
    return out
