"""``sahgrasp bench check``: its document, tables and the library's defaults it measures."""

from __future__ import annotations

import pytest

pytest.importorskip("mujoco")

from sahgrasp.bench.check import format_table, run
from sahgrasp.bench.report import summary_table


def test_bench_check_on_the_can() -> None:
    doc = run(problems_per_object=1, objects=["can"], quiet=True)
    assert doc["benchmark"] == "check"
    (row,) = doc["objects"]
    assert row["object"] == "can" and row["pieces"] == 1
    assert row["paper_grasp_holds"] == {"default": True, "light": False}
    assert row["check_cpu_median_ms"] > 0 and row["checks_per_s_one_core"] > 0
    for label in ("default", "light"):
        rates = row[label]
        assert rates["checked"] == row["solved"]
        assert rates["holds"] + sum(rates["failures"].values()) == rates["checked"]
    assert doc["settings"]["squeeze_n"] == 10.0 and doc["light_squeeze_n"] == 1.0
    assert row["dexgraspbench"]["checked"] == row["solved"]
    assert row["default_not_dexgraspbench"] <= row["default"]["holds"]
    assert "can" in summary_table(doc)
    assert format_table(doc).splitlines()[2].startswith("| can | 0.379 | 1 |")


def test_bench_plan_hold_summary_counts_targets_and_the_cross_check() -> None:
    from sahgrasp.bench.plan import HOLD_SETTINGS, _hold_cells, hold_summary

    def rates(held: list[bool]) -> dict[str, object]:
        return {"checked": len(held), "holds": sum(held), "hold_rate": sum(held) / len(held),
                "held": held, "reasons": {"turns": len(held) - sum(held)},
                "checks_per_cpu_s": 50.0}  # fmt: skip

    strong = {k: rates([True] * 10) for k in HOLD_SETTINGS}
    weak = {k: rates([True] * 8 + [False] * 2) for k in HOLD_SETTINGS}
    weak["dexgraspbench"] = rates([False] + [True] * 7 + [False] * 2)
    rows = [
        {"hold": {**strong, "mass_kg": 0.2, "default_not_dexgraspbench": 0}},
        {"hold": {**weak, "mass_kg": 0.3, "default_not_dexgraspbench": 1}},
        {"hold": None},
    ]
    summary = hold_summary(rows)
    assert summary is not None
    assert summary["default"] == {"holds": 18, "checked": 20, "objects": 2, "target": 0.95,
                                  "objects_at_target": 1}  # fmt: skip
    assert summary["light"]["objects_at_target"] == 2  # 80% meets the light squeeze's target
    assert summary["dexgraspbench"]["target"] is None
    assert summary["default_not_dexgraspbench"] == 1
    assert hold_summary([{"hold": None}]) is None
    cells = _hold_cells(rows[1]["hold"])
    assert cells[:3] == (0.3, "80% (8/10)", "80% (8/10)") and cells[7] == 1
    # A row of an older document (default and light only) still makes a table row.
    old = {"default": strong["default"], "light": strong["light"], "mass_kg": 0.2}
    assert _hold_cells(old)[3:8] == ("-", "-", "-", "-", "-")
