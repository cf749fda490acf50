"""A real browser draws an exported scene: headless Chromium renders the HTML of a solved grasp.

The screenshots stay in tests/artifacts/ (CI keeps that folder). Skipped only without Chromium.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from numpy.typing import NDArray
from PIL import Image

from sahgrasp.experiments.ik_examples import show_examples, solve_example
from sahgrasp.model.hand import Hand
from sahgrasp.viz import Viewer
from sahgrasp.viz.screenshot import find_chromium, screenshot

ARTIFACTS = Path(__file__).parent / "artifacts"
WINDOW = (800, 600)
CONTROLS_BAR_PX = 30  # meshcat's "Open Controls" bar at the top: black with white text

pytestmark = [
    pytest.mark.slow,  # starts Chromium: about 6 s
    pytest.mark.skipif(
        find_chromium() is None,
        reason="chromium is not installed (apt-get install -y chromium); the browser test needs it",
    ),
]


def rendered(html: Path, png: Path) -> NDArray[np.float64]:
    """Screenshot ``html`` to ``png`` in headless Chromium; RGB in [0, 1] below the controls."""
    screenshot(html, png, WINDOW)
    rgb = np.asarray(Image.open(png).convert("RGB"), dtype=np.float64) / 255.0
    return rgb[CONTROLS_BAR_PX:]


def red_object(rgb: NDArray[np.float64]) -> int:
    """Pixels of the can's red (0.8, 0.08, 0.1), shaded."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((r > 0.35) & (r > 2.5 * g) & (r > 2.5 * b)))


def dark_grey_palm(rgb: NDArray[np.float64]) -> int:
    """Pixels of the SAH palm's dark grey (0.35, 0.37, 0.40), shaded."""
    spread = rgb.max(axis=-1) - rgb.min(axis=-1)
    value = rgb.max(axis=-1)
    return int(np.count_nonzero((spread < 0.1) & (value > 0.1) & (value < 0.6)))


def blue_fingertips(rgb: NDArray[np.float64]) -> int:
    """Pixels of the SAH fingertips' blue (0.2, 0.45, 0.85), shaded."""
    r, g, b = rgb[..., 0], rgb[..., 1], rgb[..., 2]
    return int(np.count_nonzero((b > 0.4) & (b > r + 0.25) & (b > g + 0.1)))


@pytest.fixture(scope="module")
def shots(sah: Hand, tmp_path_factory: pytest.TempPathFactory) -> dict[str, NDArray[np.float64]]:
    ARTIFACTS.mkdir(exist_ok=True)
    work = tmp_path_factory.mktemp("browser")
    example = solve_example(sah, "can")
    assert example.result.success
    with Viewer(title="solved can") as viewer:
        show_examples(viewer, sah, [example])
        grasp = viewer.save_html(ARTIFACTS / "browser_can.html")
    with Viewer(title="empty") as viewer:
        empty = viewer.save_html(work / "empty.html")
    return {
        "grasp": rendered(grasp, ARTIFACTS / "browser_can.png"),
        "empty": rendered(empty, ARTIFACTS / "browser_empty.png"),
    }


def test_background_alone_has_none_of_the_scene_colours(shots: dict[str, NDArray]) -> None:
    empty = shots["empty"]
    assert (red_object(empty), dark_grey_palm(empty), blue_fingertips(empty)) == (0, 0, 0)


def test_chromium_draws_the_object_and_the_hand(shots: dict[str, NDArray]) -> None:
    grasp = shots["grasp"]
    pixels = grasp.shape[0] * grasp.shape[1]
    assert red_object(grasp) > 0.01 * pixels, "the can is not drawn"
    assert dark_grey_palm(grasp) > 0.01 * pixels, "the hand's palm is not drawn"
    assert blue_fingertips(grasp) > 0.0005 * pixels, "the fingertips are not drawn"
