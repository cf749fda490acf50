"""The physics hold test: paper grasps hold; broken ones (moved, opened, frictionless) do not."""

from __future__ import annotations

import dataclasses
from functools import cache

import numpy as np
import pytest

pytest.importorskip("mujoco")

from sahgrasp.errors import InvalidSettingsError
from sahgrasp.hand import Hand, load_hand
from sahgrasp.ik import IKResult, solve_ik
from sahgrasp.objects import load_object, paper_grasp
from sahgrasp.sim import HoldSettings, HoldTester, hold_test


@cache
def _sah() -> Hand:
    return load_hand("sah")


@cache
def _solved(name: str) -> IKResult:
    result = solve_ik(_sah(), paper_grasp(name))
    assert result.success
    return result


@cache
def _tester(name: str, **settings: float) -> HoldTester:
    return HoldTester(_sah(), load_object(name), HoldSettings(**settings))


def test_can_grasp_holds() -> None:
    result = _tester("can").test(_solved("can"))
    assert result.holds, result.detail
    assert result.holds_bodex
    assert result.reason == "holds"
    assert [d.direction for d in result.directions] == ["+x", "-x", "+y", "-y", "+z", "-z"]
    assert all(d.displacement_m < 0.02 and d.rotation_deg < 15 for d in result.directions)
    assert result.contact_fingers == ("thumb", "index", "middle", "ring")
    assert result.initial_penetration_m < 1e-3
    assert result.squeeze_imbalance_n < 0.05 * sum(result.squeeze_normal_n)
    assert np.mean(result.squeeze_normal_n) == pytest.approx(5.0, rel=0.05)
    assert result.mass_kg == pytest.approx(0.379, rel=0.01)


def test_can_moved_away_does_not_hold() -> None:
    obj = load_object("can")
    T = obj.T_world_object.copy()
    T[:3, 3] += [0.0, 0.0, 0.15]  # 15 cm along the can axis: the fingertips touch nothing
    result = hold_test(_sah(), _solved("can"), obj.placed(T))
    assert not result.holds and not result.holds_bodex
    assert result.reason == "no contact"


def test_can_with_thumb_opened_does_not_hold() -> None:
    hand, q = _sah(), _solved("can").q.copy()
    q[7 + hand.coordinate_index("thumb_j2")] = hand.upper[hand.coordinate_index("thumb_j2")]
    q[7 + hand.coordinate_index("thumb_j3")] = hand.upper[hand.coordinate_index("thumb_j3")]
    result = _tester("can").test(q)
    assert "thumb" not in result.contact_fingers
    assert not result.holds and not result.holds_bodex


def test_can_without_friction_does_not_hold() -> None:
    result = _tester("can", friction=0.0).test(_solved("can"))
    assert not result.holds
    assert result.reason in {"slips", "turns", "moved while settling"}


def test_result_json_has_every_direction() -> None:
    entry = _tester("can").test(_solved("can"), name="can").to_dict()
    assert entry["name"] == "can"
    assert {d["direction"] for d in entry["directions"]} == {"+x", "-x", "+y", "-y", "+z", "-z"}
    assert set(entry["directions"][0]) >= {"displacement_m", "rotation_deg", "holds"}


@pytest.mark.parametrize(
    "change",
    [
        {"friction": -0.1},
        {"friction": float("nan")},
        {"squeeze_n": 0.0},
        {"mass_kg": 0.0},
        {"timestep_s": 0.05},
        {"solver_iterations": 0},
        {"balance_friction": 2.0},
        {"pull_s": "1"},
    ],
)
def test_bad_settings_are_refused(change: dict[str, object]) -> None:
    with pytest.raises(InvalidSettingsError):
        dataclasses.replace(HoldSettings(), **change)  # type: ignore[arg-type]
