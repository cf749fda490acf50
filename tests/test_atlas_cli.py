"""``sahgrasp atlas``: --paper beside the paper's figures, radius ranges, checkpoints."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def sahgrasp(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "sahgrasp", *args], capture_output=True,
                          text=True, cwd=cwd, env=env, timeout=300, check=False)  # fmt: skip


def test_paper_prints_its_figures_beside_ours(tmp_path: Path) -> None:
    done = sahgrasp("atlas", "planar", "--paper", "--json", "out.json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert lines[0] == "planar, the paper's settings: k = 2, r = 0.125, eps = 0.4"
    charts = next(line for line in lines if line.split()[:1] == ["charts"])
    assert charts.split()[-1] == "750"  # the paper's, beside ours
    out = json.loads((tmp_path / "out.json").read_text())
    assert out["paper"]["charts"] == 750 and out["charts"] == int(charts.split()[1])
    assert (out["radius"], out["epsilon"], out["stop_reason"]) == (0.125, 0.4, "complete")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["planar", "--r", "1e-300"], "--r 1e-300 is out of range for planar: valid 0.001..1"),
        (["planar", "--r", "1e6"], "--r 1e+06 is out of range for planar: valid 0.001..1"),
        (["can", "--paper", "--r", "100"], "--r 100 is out of range for can: valid 0.1..50"),
        (["can", "--eps", "1"], "must be a finite number > 0 and < 1"),
        (["can", "--paper", "--k", "3"], "the paper reports no can atlas with k = 3"),
        (["planar", "--resume"], "--resume needs --checkpoint FILE"),
    ],
)
def test_bad_options_get_one_line_naming_the_valid_range(
    tmp_path: Path, args: list[str], message: str
) -> None:
    done = sahgrasp("atlas", *args, cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("sahgrasp atlas: error: ") and message in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_a_checkpointed_run_resumes_to_the_same_atlas(tmp_path: Path) -> None:
    first = sahgrasp("atlas", "planar", "--checkpoint", "p.npz", "--json", "a.json", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    assert (tmp_path / "p.npz").exists() and "atlas state in p.npz" in first.stdout
    again = sahgrasp("atlas", "planar", "--checkpoint", "p.npz", "--resume", "--json", "b.json",
                     cwd=tmp_path)  # fmt: skip
    assert again.returncode == 0, again.stderr
    a, b = (json.loads((tmp_path / f).read_text()) for f in ("a.json", "b.json"))
    assert (a["charts"], a["best"], a["worst"]) == (b["charts"], b["best"], b["worst"])
    other = sahgrasp("atlas", "planar", "--r", "0.2", "--checkpoint", "p.npz", "--resume",
                     cwd=tmp_path)  # fmt: skip
    assert other.returncode == 2 and "written for another problem" in other.stderr
