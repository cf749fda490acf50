"""Benchmark of the hand's kinematic queries against the raw Pinocchio calls they wrap.

The floor computes what the query returns with Pinocchio's own per-frame calls and no sahgrasp
code around them: forward kinematics plus the placement of every contact frame (point and
normal) and fingertip-sphere centre frame, for :meth:`Hand.contact_state` and
:meth:`Hand.contact_stack`; the joint Jacobians plus, for each of those frames, its placement and
its frame Jacobian, for :meth:`Hand.contact_jacobians` and :meth:`Hand.contact_stack_jacobian`
(both also return the contact state or stack). The query and its floor are timed in alternating
chunks of calls, so load from other processes falls on both alike; each reports its best chunk.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from sahgrasp.bench.report import progress_reporter
from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.progress import ProgressCallback
from sahgrasp.model.hand import Hand, load_hand
from sahgrasp.model.hands import HANDS

__all__ = ["run"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


_CHUNK = 100
"""Calls per timed chunk: short enough that some chunks run without being preempted."""


def _per_call_us(fns: tuple[Callable[[], object], ...], calls: int) -> tuple[float, ...]:
    """Best mean time per call [us] of each of ``fns`` over chunks of :data:`_CHUNK` calls.

    The functions take turns chunk by chunk, about ``calls`` calls each in all; the minimum
    over chunks filters scheduler noise.
    """
    best = [float("inf")] * len(fns)
    chunk = min(calls, _CHUNK)
    for _ in range(max(1, calls // chunk)):
        for i, fn in enumerate(fns):
            start = time.perf_counter()
            for _ in range(chunk):
                fn()
            best[i] = min(best[i], (time.perf_counter() - start) / chunk)
    return tuple(b * 1e6 for b in best)


def _hand_rows(hand: Hand, calls: int, seed: int) -> dict[str, Any]:
    q = hand.random_configuration(np.random.default_rng(seed))
    model = hand.model
    data = model.createData()  # the raw floor's own Data: the hand's is not shared state
    frames = [hand.contact_frame_id(f) for f in hand.fingers] + [
        int(model.getFrameId(f.tip_link)) for f in hand.description.fingers
    ]

    def raw_fk() -> None:
        pin.forwardKinematics(model, data, q)
        for f in frames:
            pin.updateFramePlacement(model, data, f)

    def raw_jacobians() -> None:
        pin.computeJointJacobians(model, data, q)  # also the joint placements
        for f in frames:
            pin.updateFramePlacement(model, data, f)
            pin.getFrameJacobian(model, data, f, _LWA)

    fk, fk_raw = _per_call_us((lambda: hand.contact_state(q), raw_fk), calls)
    jac, jac_raw = _per_call_us((lambda: hand.contact_jacobians(q), raw_jacobians), calls)
    # The IK's hot path: the flat (p_i, r_i) vector and its Jacobian, against the same floors.
    stack, stack_jac = _per_call_us(
        (lambda: hand.contact_stack(q), lambda: hand.contact_stack_jacobian(q)), calls
    )
    return {
        "nv": hand.nv,
        "contact_state_us": fk,
        "raw_fk_us": fk_raw,
        "contact_state_ratio": fk / fk_raw,
        "contact_jacobians_us": jac,
        "raw_jacobians_us": jac_raw,
        "contact_jacobians_ratio": jac / jac_raw,
        "contact_stack_us": stack,
        "contact_stack_ratio": stack / fk_raw,
        "contact_stack_jacobian_us": stack_jac,
        "contact_stack_jacobian_ratio": stack_jac / jac_raw,
    }


def run(
    hands: tuple[str, ...] = tuple(HANDS),
    calls: int = 20_000,
    seed: int = 0,
    quiet: bool = False,
    progress: ProgressCallback | None = None,
) -> dict[str, Any]:
    """Time the toolkit's contact queries and the raw Pinocchio floor, per call, on one core.

    Args:
        hands: Hands to time.
        calls: Timed calls per query.
        seed: Seed of the configuration.
        quiet: No progress bar on stderr.
        progress: Report progress here instead (one step per hand).

    Raises:
        InvalidSettingsError: ``calls`` is not a positive integer.
    """
    if isinstance(calls, bool) or not isinstance(calls, int) or calls < 1:
        raise InvalidSettingsError(f"calls must be a positive integer, got {calls!r}")
    rows: dict[str, Any] = {}
    with progress_reporter(progress, quiet) as report:
        for name in hands:
            if report is not None:
                report("bench kinematics: hands", len(rows), len(hands))
            rows[name] = _hand_rows(load_hand(name), calls, seed)
        if report is not None:
            report("bench kinematics: hands", len(rows), len(hands))
    return {"benchmark": "kinematics", "target_ratio": 2.0, "calls": calls, "hands": rows}
