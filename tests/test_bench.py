"""Benchmarks: missing optional peers are skipped, progress goes to stderr, a summary table."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sahgrasp.bench import atlas as bench_atlas
from sahgrasp.bench import ik as bench_ik
from sahgrasp.bench import kinematics as bench_kinematics
from sahgrasp.bench.peers import available_peers
from sahgrasp.bench.report import summary_table
from sahgrasp.core.errors import InvalidSettingsError
from sahgrasp.core.progress import StderrProgress
from sahgrasp.core.tables import format_table
from sahgrasp.ik import IKSettings
from sahgrasp.ik.learned import default_database
from sahgrasp.model.contacts import ContactTarget, GraspTarget
from sahgrasp.model.hand import Hand, load_hand

ROOT = Path(__file__).resolve().parent.parent
CLI = "import sys; from sahgrasp.cli import main; sys.exit(main(sys.argv[1:]))"


def hide_pink(monkeypatch: pytest.MonkeyPatch) -> None:
    """Make ``import pink`` fail as on a README install (no ``[bench]`` extra)."""
    monkeypatch.setitem(sys.modules, "pink", None)


# ----- tables ---------------------------------------------------------------------------------
def test_columns_are_as_wide_as_their_content() -> None:
    table = format_table(
        ("object", "solved", "ms"), [("fork", "yes", 1.5), ("can", "no (no_progress)", 12.25)]
    )
    lines = table.splitlines()
    starts = [line.index(word) for line, word in zip(lines[1:], ("yes", "no (no"), strict=True)]
    assert starts[0] == starts[1] == lines[0].index("solved")
    assert lines[1].endswith(" 1.5") and lines[2].endswith("12.25")  # numbers right-aligned
    assert lines[0].endswith("   ms")


def test_markdown_table_and_cell_formats() -> None:
    table = format_table(("a", "b"), [(True, None), (False, 2.0)], markdown=True)
    assert table.splitlines() == ["| a   | b |", "|-----|--:|", "| yes | - |", "| no  | 2 |"]
    with pytest.raises(ValueError, match="row 0 has 1 cells for 2 headers"):
        format_table(("a", "b"), [("x",)])


def test_stderr_progress_draws_one_bar_per_stage(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # bars are drawn on a terminal only
    with StderrProgress() as bar:
        for done in range(1, 4):
            bar("first", done, 3)
        bar("second", 1, None)
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "first: 100%" in captured.err and "3/3" in captured.err and "second: 1" in captured.err


# ----- bench ik -------------------------------------------------------------------------------
def test_missing_peer_is_skipped_with_the_extra_named(monkeypatch: pytest.MonkeyPatch) -> None:
    hide_pink(monkeypatch)
    ready, skipped = available_peers(["scipy", "pink", "scipy"])
    assert ready == ["scipy"]
    assert set(skipped) == {"pink"} and '".[bench]"' in skipped["pink"]
    with pytest.raises(InvalidSettingsError, match="valid: scipy, pink"):
        available_peers(["matlab"])


def test_bench_ik_without_pink_runs_the_others(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    hide_pink(monkeypatch)
    heard: list[tuple[str, int, int | None]] = []
    doc = bench_ik.run(problems=3, peer_problems=2, progress=lambda *r: heard.append(r))
    assert set(doc["skipped_peers"]) == {"pink"}
    assert "peer:scipy/sequence" in doc["runs"] and "peer:pink/sequence" not in doc["runs"]
    assert doc["runs"]["peer:scipy/sequence"]["problems"] == 2
    assert heard == [("bench ik: problems", i, 3) for i in (1, 2, 3)]
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pink" in err[0] and '".[bench]"' in err[0]
    table = summary_table(doc)
    assert "auto/sequence" in table and "peer pink skipped" in table
    learned = doc["runs"]["auto/learned"]
    assert 0.0 < learned["cpu_median_ms"] <= learned["cpu_p95_ms"]
    assert learned["cpu_us_per_iteration"] > 0.0
    lookup = doc["learned_lookup"]
    shipped = default_database(load_hand("sah"))
    assert shipped is not None
    assert (lookup["entries"], lookup["k"]) == (len(shipped.features), IKSettings().learned_starts)
    assert 0.0 <= lookup["recall"] <= 1.0
    with pytest.raises(InvalidSettingsError, match="problems"):
        bench_ik.run(problems=0)


def test_lookup_recall_counts_the_exact_neighbours_found(sah: Hand) -> None:
    database = default_database(sah)
    assert database is not None
    # Keys of entries themselves: the exact nearest is the entry, and eps=1 finds it too.
    targets = [_target_of(sah, database.configurations[i].astype(np.float64)) for i in (0, 7)]
    assert bench_ik.lookup_stats(database, sah, targets, 1)["recall"] == 1.0
    free = GraspTarget("three", targets[0].contacts[:3])
    assert bench_ik.lookup_stats(database, sah, [free], 1)["recall"] is None


def _target_of(hand: Hand, q: np.ndarray) -> GraspTarget:
    state = hand.contact_state(q)
    return GraspTarget(
        "entry",
        [ContactTarget(f, state.points[i], -state.normals[i]) for i, f in enumerate(hand.fingers)],
    )


@pytest.mark.slow
def test_bench_ik_command_without_pink_exits_cleanly(tmp_path: Path) -> None:
    fake = tmp_path / "site" / "pink"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ModuleNotFoundError(\"No module named 'pink'\")\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join((str(tmp_path / "site"), str(ROOT)))}
    out = tmp_path / "ik.json"
    done = subprocess.run(
        [sys.executable, "-c", CLI, "bench", "ik", "--problems", "2",
         "--peer-problems", "1", "--json", str(out)],
        capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "Traceback" not in done.stderr and '".[bench]"' in done.stderr
    assert set(json.loads(out.read_text())["skipped_peers"]) == {"pink"}


# ----- bench atlas and kinematics -------------------------------------------------------------
def test_bench_atlas_reports_each_case_and_tables_them() -> None:
    heard: list[tuple[str, int, int | None]] = []
    doc = bench_atlas.run(repeats=1, cases=["S2", "planar"], progress=lambda *r: heard.append(r))
    assert list(doc["cases"]) == ["S2", "planar"]
    assert heard == [("bench atlas: cases", i, 2) for i in (0, 1, 2)]
    lines = summary_table(doc).splitlines()
    assert lines[0] == "bench atlas" and lines[1].split()[:3] == ["case", "charts", "complete"]
    assert [line.split()[0] for line in lines[2:]] == ["S2", "planar"]
    assert "one-chart [s]" in lines[1]  # the wave engine beside the one-chart engine
    assert lines[2].split()[5] == str(doc["cases"]["S2"]["one_chart"]["charts"])
    with pytest.raises(InvalidSettingsError, match="valid: S2, S3, planar"):
        bench_atlas.run(cases=["S4"])


@pytest.mark.slow
def test_bench_atlas_times_a_whole_run_with_checking_workers(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """The paper-scale row, on a small bottle atlas: one run end to end, checks beside it."""
    monkeypatch.setattr(bench_atlas, "PAPER_SCALE_CASES", (("bottle", 2, 0.05, 0.1, 1, 300.0),))
    label = "sah_bottle_k2_r0.05_L0.1_whole"
    row = bench_atlas.run(repeats=1, cases=[label], quiet=True)["cases"][label]
    assert row["complete"] and 0 < row["valid"] <= row["charts"]
    assert row["workers"] == 1 and row["atlas_seconds"] < row["seconds"]
    assert row["whole_time_ok"] == (row["seconds"] <= 300.0)
    table = summary_table(bench_atlas.run(repeats=1, cases=[label], quiet=True))
    assert "whole run, 1 checking process(es): target 300 s (paper 1400 charts, 45 s)" in table


def test_stage_profile_gives_nested_shares_of_one_build() -> None:
    shares = bench_atlas.stage_profile("S2")
    assert shares.pop("charts") == 1255  # the same atlas as the timed build
    assert set(shares) == set(bench_atlas.STAGES)
    assert all(0.0 < share < 1.0 for share in shares.values())
    parts = ("neighbour search", "branch test of the neighbours")
    assert shares["adding a chart (all of the above)"] > sum(shares[p] for p in parts)
    with pytest.raises(InvalidSettingsError, match="S2"):
        bench_atlas.stage_profile("S4")


def test_bench_atlas_draws_progress_on_a_terminal_unless_quiet(
    capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from sahgrasp.bench import report

    bench_atlas.run(repeats=1, cases=["S2"])
    assert capsys.readouterr().err == ""  # stderr is no terminal here: no bars in a log
    monkeypatch.setattr(report, "_is_terminal", lambda stream: True)
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)  # the bars draw on a terminal only
    bench_atlas.run(repeats=1, cases=["S2"])
    assert "bench atlas: cases" in capsys.readouterr().err
    bench_atlas.run(repeats=1, cases=["S2"], quiet=True)
    assert capsys.readouterr().err == ""


def test_kinematics_table_and_progress() -> None:
    heard: list[tuple[str, int, int | None]] = []
    doc = bench_kinematics.run(hands=("sah",), calls=5, progress=lambda *r: heard.append(r))
    assert heard == [("bench kinematics: hands", 0, 1), ("bench kinematics: hands", 1, 1)]
    lines = summary_table(doc).splitlines()
    assert lines[0].startswith("bench kinematics: 5 calls") and lines[2].split()[0] == "sah"


def test_sequence_table_and_unknown_documents() -> None:
    row = {"wall_seconds": 2.0, "ik_runs": 100, "ik_runs_per_second": 50.0}
    doc: dict[str, Any] = {
        "benchmark": "sequence",
        "hand": "sah",
        "workers": {"1": row, "2": {**row, "wall_seconds": 1.25}},
        "speedup": 1.6,
        "paper_scale": {"cluster_workers": 16, "hours": 3.5},
    }
    lines = summary_table(doc).splitlines()
    assert [line.split()[:2] for line in lines[2:4]] == [["1", "2"], ["2", "1.25"]]
    assert lines[-1] == "speed-up 1.6; paper scale on 16 workers: 3.5 h"
    with pytest.raises(
        InvalidSettingsError, match=r"valid: (\w+, )*ik, atlas, kinematics, sequence"
    ):
        summary_table({"benchmark": "nope"})


# ----- solve at scale -------------------------------------------------------------------------
def test_bench_solve_runs_the_chosen_worker_counts() -> None:
    pytest.importorskip("psutil")
    from sahgrasp.bench import solve as bench_solve

    reports: list[tuple[str, int, int | None]] = []
    doc = bench_solve.run(
        problems=6, lines=0, dask=False, workers=[1],
        progress=lambda stage, done, total: reports.append((stage, done, total)),
    )  # fmt: skip
    assert reports[-1] == ("bench solve: --workers 1", 6, 6)
    assert all(0 <= done <= total for _, done, total in reports)  # type: ignore[operator]
    assert [case["where"] for case in doc["cases"]] == ["--workers 1"]
    assert doc["cases"][0]["lines"] == 6 and doc["cases"][0]["peak_rss_mb"] > 0
    assert doc["speedup_1_to_2_workers"] is None
    assert "speed-up 1 -> 2 workers not run" in summary_table(doc)
