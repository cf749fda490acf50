"""The scenes' colours: the stored RdYlGn table against matplotlib's colour map."""

from __future__ import annotations

import numpy as np
import pytest

from sahgrasp.viz.colors import RDYLGN_RGB, hex_color, quality_colormap, quality_colors


def test_the_stored_rdylgn_equals_matplotlibs_within_one_level() -> None:
    colormaps = pytest.importorskip("matplotlib").colormaps
    x = np.concatenate([np.linspace(0.0, 1.0, 20001), [1 / 256, 255 / 256, 0.5, 1.0, 0.0]])
    ours = quality_colormap(x)
    theirs = colormaps["RdYlGn"](x)[:, :3]
    assert np.abs(ours - theirs).max() <= 1 / 255
    assert [hex_color(c) for c in ours] == [hex_color(c) for c in theirs]


def test_the_map_runs_from_red_through_yellow_to_green() -> None:
    ends = quality_colormap([0.0, 1.0])
    np.testing.assert_allclose(ends * 255, [RDYLGN_RGB[0], RDYLGN_RGB[-1]])
    middle = quality_colormap([0.5])[0] * 255  # the table's entry 128 of 0..255
    assert np.all(np.abs(middle - RDYLGN_RGB[5]) < 5) and middle[2] < RDYLGN_RGB[5][2]
    np.testing.assert_array_equal(quality_colormap([-0.5, 1.5]), quality_colormap([0.0, 1.0]))


def test_singular_values_are_black_and_the_rest_span_the_map() -> None:
    colors = quality_colors(np.array([2.0, 4.0, 0.1, 3.0]), singular_below=1.0)
    np.testing.assert_array_equal(colors[2], [0.0, 0.0, 0.0])
    np.testing.assert_allclose(colors[[0, 1]] * 255, [RDYLGN_RGB[0], RDYLGN_RGB[-1]])
    with pytest.raises(ValueError, match="finite 1-D"):
        quality_colors(np.array([np.nan]), 0.0)
