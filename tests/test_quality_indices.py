"""The registry of quality indices: adding one is one call, and every user of indices knows it."""

from __future__ import annotations

import argparse
import subprocess
import sys
from collections.abc import Iterator

import numpy as np
import pytest
from numpy.typing import NDArray

from sahgrasp.cli import atlas as atlas_command
from sahgrasp.core.errors import QualityError
from sahgrasp.experiments.arguments import INDEX_CHOICES
from sahgrasp.experiments.report import summary
from sahgrasp.optimization.optimizer import OptimizationSettings, optimize
from sahgrasp.optimization.planar import make_planar_problem
from sahgrasp.quality.ellipsoids import (
    INDICES,
    QUALITY_INDICES,
    SINGULAR_THRESHOLDS,
    QualityIndex,
    ellipsoid_indices,
    register_index,
)
from sahgrasp.quality.indices import Ellipsoids


def _largest_semiaxis(ellipsoids: Ellipsoids) -> NDArray[np.float64]:
    return ellipsoids.semi_axes[..., 0]


TEST_INDEX = QualityIndex("max_semiaxis", _largest_semiaxis, 0.05, "largest semi-axis (a test)")


@pytest.fixture
def test_index() -> Iterator[QualityIndex]:
    """The test index, registered for one test: the single place that adds it."""
    register_index(TEST_INDEX)
    try:
        yield TEST_INDEX
    finally:
        QUALITY_INDICES.unregister(TEST_INDEX.name)


def test_the_paper_indices_are_registered_in_the_order_of_fig_9() -> None:
    assert tuple(QUALITY_INDICES) == INDICES == ("inverse_condition", "volume", "min_semiaxis")
    assert dict(SINGULAR_THRESHOLDS) == {"inverse_condition": 1e-3, "volume": 1e-4,
                                         "min_semiaxis": 1e-3}  # fmt: skip
    assert all(QUALITY_INDICES[name].description for name in INDICES)
    assert INDEX_CHOICES == INDICES


def test_an_added_index_is_known_to_the_ellipsoids(test_index: QualityIndex) -> None:
    rng = np.random.default_rng(0)
    m = ellipsoid_indices(rng.normal(size=(5, 6, 4)), rng.normal(size=(5, 3, 4)))
    assert np.array_equal(m.index("max_semiaxis"), m.semi_axes[:, 0])
    assert np.array_equal(m.singular("max_semiaxis"), m.semi_axes[:, 0] < 0.05)
    assert SINGULAR_THRESHOLDS["max_semiaxis"] == 0.05
    # The built-in indices are the ellipsoid's fields, bit for bit.
    assert m.index("volume") is m.volume


def test_an_added_index_is_a_command_line_choice(test_index: QualityIndex) -> None:
    parser = argparse.ArgumentParser(prog="sahgrasp")
    commands = parser.add_subparsers(dest="command")
    atlas_command.add_parser(commands)  # the parser of ``sahgrasp atlas``
    args = parser.parse_args(["atlas", "planar", "--index", "max_semiaxis"])
    assert args.index == "max_semiaxis"
    help_text = commands.choices["atlas"].format_help()
    assert "max_semiaxis" in help_text
    assert "max_semiaxis" in INDEX_CHOICES  # the view taken at import sees it


def test_an_added_index_is_optimised_and_reported(test_index: QualityIndex) -> None:
    settings = OptimizationSettings(radius=0.125, epsilon=0.4, index="max_semiaxis", max_charts=60)
    result = optimize(make_planar_problem(), settings)
    assert result.quality is not None
    values = result.quality.index("max_semiaxis")
    assert result.all_values[result.best] == values[result.valid].max()
    out = summary("planar", result)
    assert set(out["indices"]) == {*INDICES, "max_semiaxis"}
    assert out["best"]["singular"] == bool(values[result.best] < 0.05)


def test_an_index_unregistered_is_gone_everywhere() -> None:
    register_index(TEST_INDEX)
    QUALITY_INDICES.unregister(TEST_INDEX.name)
    assert "max_semiaxis" not in INDEX_CHOICES and "max_semiaxis" not in SINGULAR_THRESHOLDS
    m = ellipsoid_indices(np.eye(3), np.eye(3))
    with pytest.raises(QualityError, match="unknown quality index 'max_semiaxis'; valid: inverse"):
        m.index("max_semiaxis")


def test_bad_registrations_are_typed_errors(test_index: QualityIndex) -> None:
    with pytest.raises(QualityError, match="already registered"):
        register_index(test_index)
    with pytest.raises(QualityError, match="non-empty name"):
        register_index(QualityIndex("", _largest_semiaxis, 0.0, "nameless"))
    with pytest.raises(QualityError, match="callable"):
        QualityIndex("x", 3, 0.0, "")  # type: ignore[arg-type]
    with pytest.raises(QualityError, match="singular_below must be a number"):
        QualityIndex("x", _largest_semiaxis, "1e-3", "")  # type: ignore[arg-type]
    with pytest.raises(QualityError, match="takes a QualityIndex"):
        register_index("volume")  # type: ignore[arg-type]


def test_listing_the_indices_loads_no_numpy() -> None:
    code = (
        "import sys; from sahgrasp.experiments.arguments import INDEX_CHOICES; "
        "print(','.join(INDEX_CHOICES), 'numpy' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.split() == ["inverse_condition,volume,min_semiaxis", "False"]
