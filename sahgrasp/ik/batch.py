"""Solve many IK problems over a process pool, with the same results for any worker count.

Workers receive the picklable :class:`HandDescription` and rebuild the hand once per process
(Pinocchio's GeometryModel does not pickle). Each problem's random initial configurations are
seeded from ``(seed, problem index)``, so a result never depends on which worker solved it.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import replace
from typing import Any

import numpy as np

from sahgrasp.contacts import GraspTarget
from sahgrasp.errors import InvalidTargetError
from sahgrasp.hand import Hand, HandDescription
from sahgrasp.ik.initial import Sequence as PoseSequence
from sahgrasp.ik.solver import IKResult, IKSettings, solve_ik

__all__ = ["invalid_result", "solve_many"]

_HANDS: dict[str, Hand] = {}


def _worker_hand(description: HandDescription) -> Hand:
    key = description.digest()
    if key not in _HANDS:
        _HANDS[key] = Hand(description)
    return _HANDS[key]


def invalid_result(hand: Hand, name: str) -> IKResult:
    """The result of a problem refused as invalid input (nothing was solved)."""
    nan = np.full(len(hand.fingers), np.nan)
    return IKResult(
        name=name, success=False, reason="invalid_input", q=hand.configuration(),
        position_errors_m=nan, centre_errors_m=nan, inits_used=0, iterations=0, time_s=0.0,
        collision_free=False, fingers=hand.fingers,
    )  # fmt: skip


def _solve_one(
    description: HandDescription,
    target: GraspTarget,
    settings: IKSettings,
    sequence: PoseSequence | None,
    index: int,
) -> IKResult:
    hand = _worker_hand(description)
    problem_seed = np.random.SeedSequence([settings.seed, index]).generate_state(1)[0]
    seeded = replace(settings, seed=int(problem_seed))
    try:
        return solve_ik(hand, target, seeded, sequence)
    except InvalidTargetError:
        return invalid_result(hand, target.name)


def solve_many(
    hand: Hand,
    targets: Sequence[GraspTarget],
    settings: IKSettings | None = None,
    sequence: PoseSequence | None = None,
    workers: int = 1,
    executor: Executor | None = None,
) -> list[IKResult]:
    """Solve every target; ``workers > 1`` (or an ``executor``) spreads them over processes.

    Targets whose fingers do not match the hand get a ``reason="invalid_input"`` result.
    """
    settings = settings or IKSettings()
    jobs = [(hand.description, t, settings, sequence, i) for i, t in enumerate(targets)]
    if executor is None and workers <= 1:
        _HANDS.setdefault(hand.description.digest(), hand)
        return [_solve_one(*job) for job in jobs]
    if executor is not None:
        return list(_map(executor, jobs))
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(_map(pool, jobs))


def _map(executor: Executor, jobs: list[tuple[Any, ...]]) -> Iterator[IKResult]:
    if not jobs:
        return iter(())
    return executor.map(_solve_one, *zip(*jobs, strict=True))
