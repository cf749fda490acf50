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
    assert "can" in summary_table(doc)
    assert format_table(doc).splitlines()[2].startswith("| can | 0.379 | 1 |")
