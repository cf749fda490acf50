"""The screenshots of examples/README.md have the sizes it says they were taken at."""

from __future__ import annotations

import re
import struct
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def png_size(path: Path) -> tuple[int, int]:
    """Width and height [px] from a PNG's header chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR", path
    width, height = struct.unpack(">II", head[16:24])
    return int(width), int(height)


def test_the_screenshots_have_the_sizes_the_readme_gives() -> None:
    readme = " ".join((ROOT / "examples" / "README.md").read_text(encoding="utf-8").split())
    grasp = re.search(r"the grasp scenes at `--size (\d+)x(\d+)`", readme)
    atlas = re.search(r"the atlas scenes \(`optimize_\*\.py --html OUT`\) at the default `--size "
                      r"(\d+)x(\d+)`", readme)  # fmt: skip
    assert grasp and atlas, "examples/README.md no longer says the screenshot sizes"
    images = sorted((ROOT / "examples" / "img").glob("*.png"))
    assert images
    for image in images:
        said = atlas if image.name.startswith("optimize_") else grasp
        assert png_size(image) == (int(said[1]), int(said[2])), image.name
        assert f"img/{image.name}" in readme, f"{image.name} is not shown in examples/README.md"
