"""``sahgrasp.sim.verify``: the hold test as the planner's check, and ``plan --verify physics``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("mujoco")

from sahgrasp.model.hand import load_hand
from sahgrasp.objects import load_object
from sahgrasp.planner import PlanSettings, plan_grasps
from sahgrasp.sim import DirectionResult, HoldResult, HoldSettings
from sahgrasp.sim.verify import PhysicsCheck, hold_margin, hold_rates, hold_verdict


def _result(settle: tuple[float, float], pulls: list[tuple[float, float]]) -> HoldResult:
    s = HoldSettings()
    directions = tuple(
        DirectionResult(
            f"+{k}", m, a, m < s.max_displacement_m and a < s.max_rotation_deg, True, 1.0
        )
        for k, (m, a) in enumerate(pulls)
    )
    holds = all(d.holds for d in directions)
    return HoldResult(
        name="g", holds=holds, holds_bodex=True, reason="holds" if holds else "turns",
        detail="", directions=directions, initial_penetration_m=0.0, penetrating_geom=None,
        settle_displacement_m=settle[0], settle_rotation_deg=settle[1], mass_kg=0.1,
        contact_fingers=("thumb", "index"), squeeze_normal_n=(10.0, 10.0),
        squeeze_imbalance_n=0.0, squeeze_imbalance_nm=0.0, torque_limited=False,
        simulated_s=1.0, time_s=0.0,
    )  # fmt: skip


def test_margin_is_the_worst_motion_against_its_threshold() -> None:
    s = HoldSettings()
    # 5 mm of 20 and 6 deg of 15 in one pull: the rotation (0.4) is the worst ratio.
    assert hold_margin(_result((0.001, 1.0), [(0.005, 6.0), (0.002, 1.0)]), s) == pytest.approx(0.6)
    # The settling counts too.
    assert hold_margin(_result((0.010, 0.0), [(0.001, 0.0)]), s) == pytest.approx(0.5)
    failing = _result((0.0, 0.0), [(0.030, 1.0)])
    assert not failing.holds
    assert hold_margin(failing, s) == pytest.approx(-0.5)
    assert hold_margin(_result((0.0, 0.0), []), s) == -1.0
    verdict = hold_verdict(failing, s)
    assert verdict["holds"] is False
    assert verdict["max_displacement_m"] == pytest.approx(0.030)
    json.dumps(verdict)


def test_planner_keeps_only_grasps_that_hold_ranked_by_margin() -> None:
    hand = load_hand("sah")
    can = load_object("can")
    settings = PlanSettings(candidates=24, grasps=4, seed=3)
    check = PhysicsCheck(hand, can, HoldSettings())
    plan = plan_grasps(hand, can, settings, check=check)
    assert plan.grasps
    margins = [g.quality["check"] for g in plan.grasps]
    assert margins == sorted(margins, reverse=True)
    assert all(0.0 < m <= 1.0 for m in margins)
    document = check.annotate(plan.to_dict())
    assert all(g["hold"]["holds"] for g in document["grasps"])
    assert document["summary"]["hold_checked"] >= len(plan.grasps)
    # The verdict is the hold test's, found again by an independent tester.
    rates = hold_rates(hand, can, [g.q for g in plan.grasps], {"default": HoldSettings()})
    assert rates["default"]["holds"] == len(plan.grasps)
    assert rates["default"]["held"] == [True] * len(plan.grasps)
    assert rates["default"]["mass_kg"] == pytest.approx(0.379, rel=0.01)  # the can at 1000 kg/m^3
    # Without friction nothing holds: the check drops every grasp.
    frictionless = PhysicsCheck(hand, can, HoldSettings(friction=0.0))
    assert not plan_grasps(hand, can, settings, check=frictionless).grasps
    assert frictionless.checked > 0


def test_plan_verify_physics_json_and_option_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from sahgrasp.cli import main

    out = tmp_path / "plan.json"
    code = main(["plan", "can", "--candidates", "6", "--grasps", "1", "--verify", "physics",
                 "--quiet", "--json", str(out)])  # fmt: skip
    document = json.loads(out.read_text())
    assert code == (0 if document["grasps"] else 1)
    for grasp in document["grasps"]:
        assert grasp["hold"]["holds"] is True
        assert grasp["hold"]["squeeze_n"] == HoldSettings().squeeze_n
    assert document["summary"]["hold_checked"] >= len(document["grasps"])
    capsys.readouterr()
    assert main(["plan", "can", "--light", "--quiet"]) == 2
    assert "need --verify physics" in capsys.readouterr().err
    assert main(["plan", "can", "--max-candidates", "12", "--quiet"]) == 2
    assert "need --verify physics" in capsys.readouterr().err


def test_plan_verify_physics_on_a_folder(tmp_path: Path) -> None:
    import trimesh

    from sahgrasp.cli import main

    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(folder / "box.stl")
    out = tmp_path / "plans.jsonl"
    main(["plan", str(folder), "--candidates", "6", "--grasps", "1", "--verify", "physics",
          "--quiet", "--json", str(out)])  # fmt: skip
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    assert lines[0]["settings"]["verify"]["physics"]["squeeze_n"] == HoldSettings().squeeze_n
    document = lines[1]
    assert "hold_checked" in document["summary"]
    assert all(g["hold"]["holds"] for g in document["grasps"])


@pytest.mark.slow
def test_plan_verify_physics_batches_are_the_same_on_one_and_two_workers(tmp_path: Path) -> None:
    import trimesh

    from sahgrasp.cli import main

    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.cylinder(radius=0.03, height=0.1, sections=32).export(folder / "cyl.stl")
    trimesh.creation.box(extents=(0.05, 0.06, 0.08)).export(folder / "box.stl")
    args = ["--candidates", "4", "--grasps", "4", "--max-candidates", "12", "--verify",
            "physics", "--seed", "1", "--quiet"]  # fmt: skip
    documents = []
    for workers in ("1", "2"):
        out = tmp_path / f"plans{workers}.jsonl"
        main(["plan", str(folder), "--workers", workers, "--json", str(out), *args])
        lines = [json.loads(line) for line in out.read_text().splitlines()]
        assert lines[0]["settings"]["verify"]["max_candidates"] == 12
        documents.append(lines[1:])
    one, two = documents
    assert [d["object"] for d in one] == [d["object"] for d in two]
    for a, b in zip(one, two, strict=True):
        assert [g["seed"] for g in a["grasps"]] == [g["seed"] for g in b["grasps"]]
        assert a["summary"]["candidates"] == b["summary"]["candidates"]
        assert a["summary"]["candidates"] in (4, 8, 12)
        # Further batches only while fewer than asked hold.
        assert len(a["grasps"]) == 4 or a["summary"]["candidates"] == 12
