"""Benchmark of the hand's kinematic queries against the raw Pinocchio calls they wrap.

The floor performs the same Pinocchio calls with no sahgrasp code around them: forward kinematics
plus the placement of every contact and centre frame, and the joint Jacobians plus the frame
Jacobian of every contact and centre frame.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pinocchio as pin

from sahgrasp.hand import Hand, load_hand

__all__ = ["run"]

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def _per_call_us(fn: Callable[[], object], calls: int, repeats: int = 5) -> float:
    """Best-of-``repeats`` mean time per call [us] (the minimum filters scheduler noise)."""
    best = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(calls):
            fn()
        best = min(best, (time.perf_counter() - start) / calls)
    return best * 1e6


def _hand_rows(hand: Hand, calls: int, seed: int) -> dict[str, Any]:
    q = hand.random_configuration(np.random.default_rng(seed))
    model, data = hand.model, hand.data
    frames = [hand.contact_frame_id(f) for f in hand.fingers] + [
        int(model.getFrameId(f.tip_link)) for f in hand.description.fingers
    ]

    def raw_fk() -> None:
        pin.forwardKinematics(model, data, q)
        for f in frames:
            pin.updateFramePlacement(model, data, f)

    def raw_jacobians() -> None:
        pin.computeJointJacobians(model, data, q)
        for f in frames:
            pin.getFrameJacobian(model, data, f, _LWA)

    fk = _per_call_us(lambda: hand.contact_state(q), calls)
    fk_raw = _per_call_us(raw_fk, calls)
    jac = _per_call_us(lambda: hand.contact_jacobians(q), calls)
    jac_raw = _per_call_us(raw_jacobians, calls)
    return {
        "nv": hand.nv,
        "contact_state_us": fk,
        "raw_fk_us": fk_raw,
        "contact_state_ratio": fk / fk_raw,
        "contact_jacobians_us": jac,
        "raw_jacobians_us": jac_raw,
        "contact_jacobians_ratio": jac / jac_raw,
    }


def run(hands: tuple[str, ...] = ("sah", "allegro"), calls: int = 20_000, seed: int = 0) -> dict:
    """Time the toolkit's contact queries and the raw Pinocchio floor, per call, on one core."""
    return {
        "benchmark": "kinematics",
        "target_ratio": 2.0,
        "calls": calls,
        "hands": {name: _hand_rows(load_hand(name), calls, seed) for name in hands},
    }
