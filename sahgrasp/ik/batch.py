"""Solve many IK problems over a process pool, with the same results for any worker count.

Workers receive the picklable :class:`HandDescription` and its digest and rebuild the hand once
per worker thread (Pinocchio's GeometryModel does not pickle); :func:`worker_hand` also serves the
offline sequence search. A problem's random initial configurations are seeded from the settings'
seed and the problem's content (:func:`sahgrasp.ik.starts.problem_seed`), and the collision
queries carry no state between problems, so a result depends neither on which worker solved it
nor on the problems solved before it.
"""

from __future__ import annotations

import threading
from collections.abc import Iterator, Sequence
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Any

import numpy as np

from sahgrasp.contacts import GraspTarget
from sahgrasp.errors import InvalidTargetError, SequenceFileError
from sahgrasp.hand import BUILTIN_HANDS, Hand, HandDescription, load_hand
from sahgrasp.ik.initial import Sequence as PoseSequence
from sahgrasp.ik.solver import IKResult, IKSettings, solve_ik

__all__ = ["invalid_result", "solve_many", "worker_hand"]


class _WorkerHands(threading.local):
    def __init__(self) -> None:
        self.hands: dict[str, Hand] = {}


_HANDS = _WorkerHands()


def worker_hand(description: HandDescription, digest: str) -> Hand:
    """The hand of ``description``, built once per worker thread and kept by its ``digest``.

    A built-in hand whose URDF path does not exist on this machine (a cluster node with another
    install prefix) is rebuilt from this machine's copy. Either way the hand must have ``digest``.

    Raises:
        SequenceFileError: This worker's hand is not the one the work was started with.
    """
    hand = _HANDS.hands.get(digest)
    if hand is None:
        local = description
        if not description.urdf_path.is_file() and description.name in BUILTIN_HANDS:
            local = load_hand(description.name).description
        hand = load_hand(local)
        found = hand.description.digest()
        if found != digest:
            raise SequenceFileError(
                f"worker's hand {description.name!r} has digest {found[:12]}, the caller's has "
                f"{digest[:12]}: install the same sahgrasp and URDF on every worker"
            )
        _HANDS.hands[digest] = hand
    return hand


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
    digest: str,
    target: GraspTarget,
    settings: IKSettings,
    sequence: PoseSequence | None,
) -> IKResult:
    hand = worker_hand(description, digest)
    try:
        return solve_ik(hand, target, settings, sequence)
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
    digest = hand.description.digest()
    jobs = [(hand.description, digest, t, settings, sequence) for t in targets]
    if executor is None and workers <= 1:
        _HANDS.hands.setdefault(digest, hand)
        return [_solve_one(*job) for job in jobs]
    if executor is not None:
        return list(_map(executor, jobs))
    with ProcessPoolExecutor(max_workers=workers) as pool:
        return list(_map(pool, jobs))


def _map(executor: Executor, jobs: list[tuple[Any, ...]]) -> Iterator[IKResult]:
    if not jobs:
        return iter(())
    return executor.map(_solve_one, *zip(*jobs, strict=True))
