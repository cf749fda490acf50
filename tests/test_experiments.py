"""The experiments layer: its options and defaults agree with the library (its place in the
layering is checked by tests/test_layering.py)."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

import pytest

from sahgrasp.experiments.arguments import (
    ATLAS_DEFAULTS,
    INDEX_CHOICES,
    add_atlas_arguments,
    atlas_geometry,
)
from sahgrasp.experiments.setups import EXPERIMENTS, experiment_settings
from sahgrasp.quality.ellipsoids import INDICES

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.slow
def test_viz_does_not_load_the_ik_or_the_experiments() -> None:
    code = "import sys, sahgrasp.viz; print(sorted(m for m in sys.modules if m.startswith(("
    code += "'sahgrasp.ik', 'sahgrasp.experiments'))))"
    env = {"PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                          check=True, cwd=ROOT)  # fmt: skip
    assert done.stdout.strip() == "[]"


def test_option_choices_and_defaults_match_the_library() -> None:
    assert INDEX_CHOICES == INDICES
    assert set(ATLAS_DEFAULTS) == set(EXPERIMENTS)
    for name, (radius, epsilon) in ATLAS_DEFAULTS.items():
        settings = experiment_settings(name)
        assert (settings.radius, settings.epsilon) == (radius, epsilon)


def test_atlas_options_default_per_experiment() -> None:
    one = argparse.ArgumentParser()
    add_atlas_arguments(one, ["planar"])
    args = one.parse_args([])
    assert (args.r, args.eps, args.k, args.index) == (0.125, 0.4, 2, "volume")
    several = argparse.ArgumentParser()
    add_atlas_arguments(several, list(ATLAS_DEFAULTS))
    args = several.parse_args(["--eps", "0.3"])
    assert atlas_geometry("can", args) == (0.1, 0.3)
    assert "planar 0.125" in several.format_help()
    with pytest.raises(SystemExit):
        several.parse_args(["--r", "-1"])
