import json

import numpy as np
import pinocchio as pin
import pytest

from sahgrasp.bench.grasps import (
    PENETRATION_TOLERANCE_M,
    RUNS,
    ObjectPenetration,
    format_table,
    run,
)
from sahgrasp.core.errors import InvalidSettingsError, InvalidTargetError
from sahgrasp.ik import solve_ik
from sahgrasp.model.hand import Hand
from sahgrasp.objects import load_object, paper_grasp, placement
from sahgrasp.objects.targets import load_targets

ROW_FIELDS = {
    "object", "contact_set_seed", "sampling_s", "runs", "time_ratio_mean", "time_ratio_median",
    "same_starts", "hold",
}  # fmt: skip
RUN_FIELDS = {
    "problems", "solved", "success_rate", "first_start_success_rate", "mean_starts",
    "mean_starts_solved", "median_time_ms", "mean_time_ms", "p95_time_ms", "mean_iterations",
    "reasons", "penetration", "median_cpu_ms", "mean_cpu_ms",
}  # fmt: skip
PENETRATION_FIELDS = {
    "claimed", "penetrating", "penetrating_rate", "usable_rate", "median_penetrating_depth_mm",
    "max_link_depth_mm",
    "max_fingertip_depth_mm", "deepest_links",
}  # fmt: skip


def test_bench_on_three_problems_returns_and_writes_the_documented_fields(tmp_path):
    out, targets = tmp_path / "grasps.json", tmp_path / "targets.json"
    document = run(
        problems_per_object=3,
        objects=("can",),
        json_out=str(out),
        quiet=True,
        targets_out=str(targets),
    )
    assert json.loads(out.read_text()) == json.loads(json.dumps(document))
    problems = load_targets(targets).problems
    assert [p.name for p in problems] == ["can-0", "can-1", "can-2"]
    assert document["benchmark"] == "grasps" and document["problems_per_object"] == 3
    (row,) = document["objects"]
    assert set(row) == ROW_FIELDS and set(row["runs"]) == set(RUNS)
    if row["hold"] is not None:  # with MuJoCo: the solved grasps hold-tested twice
        solved = row["runs"][RUNS[1]]["solved"]
        assert {k: row["hold"][k]["checked"] for k in ("default", "light")} == {
            "default": solved,
            "light": solved,
        }
    for stats in row["runs"].values():
        assert set(stats) == RUN_FIELDS
        assert set(stats["penetration"]) == PENETRATION_FIELDS
        assert stats["problems"] == 3 and sum(stats["reasons"].values()) == 3
        assert stats["penetration"]["claimed"] == stats["solved"]
        assert 0.0 <= stats["first_start_success_rate"] <= stats["success_rate"] <= 1.0
    alike = row["same_starts"]
    assert set(alike) == {"sets", "cpu_ratio_total", "cpu_ratio_median"}
    assert 0 <= alike["sets"] <= 3 and (alike["sets"] == 0) == (alike["cpu_ratio_total"] is None)
    # Checked independently of the solver: no claimed solution with the object penetrates it.
    assert row["runs"]["with_object"]["penetration"]["penetrating"] == 0
    table = format_table(document).splitlines()
    assert len(table) == 2 + 2 and table[2].startswith("| can | without object |")


def test_bench_rejects_bad_arguments_with_typed_errors():
    with pytest.raises(InvalidSettingsError, match="problems_per_object"):
        run(problems_per_object=0, quiet=True)
    with pytest.raises(InvalidTargetError, match="valid names"):
        run(problems_per_object=1, objects=("anvil",), quiet=True)


@pytest.fixture(scope="module")
def can_solution(sah: Hand) -> np.ndarray:
    result = solve_ik(sah, paper_grasp("can"))
    assert result.success
    return result.q


def test_plain_urdf_fingertips_match_the_solvers_sphere_centres(sah: Hand, can_solution):
    check = ObjectPenetration(sah, load_object("can"))
    pin.framesForwardKinematics(check.model, check.data, check.plain_configuration(can_solution))
    tips = [check.data.oMf[check.model.getFrameId(f.tip_link)].translation for f in
            sah.description.fingers]  # fmt: skip
    np.testing.assert_allclose(tips, sah.contact_state(can_solution).centres, atol=1e-12)


def test_the_paper_can_grasp_does_not_penetrate_and_a_can_in_the_palm_does(sah: Hand, can_solution):
    depths = ObjectPenetration(sah, load_object("can")).depths(can_solution)
    tips = {f.tip_link for f in sah.description.fingers}
    assert all(d <= PENETRATION_TOLERANCE_M for link, d in depths.items() if link not in tips)
    # The palm box (65.7 x 120 x 130 mm about (-11.85, 0, 65) mm in the palm frame) around a can
    # of radius 33 mm standing at its centre, the hand at the origin.
    can_in_palm = load_object("can", placement(None, (-0.01185, 0.0, 0.0)))
    depths = ObjectPenetration(sah, can_in_palm).depths(sah.configuration())
    assert depths["palm"] > 0.02
