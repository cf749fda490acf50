"""Optional dependencies: one typed error naming the extra; in a command, one line and exit 2."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib import metadata
from pathlib import Path
from typing import Any

import pytest

from sahgrasp.core import extras
from sahgrasp.core.errors import MissingExtraError, SahGraspError
from sahgrasp.core.extras import (
    has_extra,
    install_command,
    install_hint,
    is_editable_install,
    require_extra,
)

ROOT = Path(__file__).resolve().parents[1]


def test_a_missing_module_raises_one_typed_error_naming_its_extra(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setitem(extras.EXTRAS, "nothing", ("sahgrasp_no_such_module", "Nothing"))
    with pytest.raises(MissingExtraError) as caught:
        require_extra("nothing", "the test")
    assert caught.value.extra == "nothing"
    assert str(caught.value) == 'the test needs Nothing: pip install "sahgrasp[nothing]"'
    assert isinstance(caught.value, SahGraspError) and isinstance(caught.value, ImportError)
    assert not has_extra("nothing")
    assert install_hint("plot") == 'pip install "sahgrasp[plot]"'


def test_an_installed_extra_gives_its_module() -> None:
    assert require_extra("plot", "the test").__name__ == "matplotlib"
    assert has_extra("cluster")


def _blocked(modules: list[str], code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """Run ``code`` in a fresh interpreter in which ``modules`` cannot be imported."""
    block = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in modules)
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-c", block + code], capture_output=True, text=True, env=env, cwd=cwd
    )


def _one_line(done: subprocess.CompletedProcess[str], pattern: str) -> None:
    assert "Traceback" not in done.stderr, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1, done.stderr
    assert re.search(pattern, lines[0]), lines[0]
    assert done.returncode == 2


def test_a_scheduler_without_dask_is_one_line_naming_the_cluster_extra(tmp_path: Path) -> None:
    from sahgrasp.ik import random_problems
    from sahgrasp.model.hand import load_hand
    from sahgrasp.objects.targets import save_targets

    save_targets(tmp_path / "t.json", "sah", random_problems(load_hand("sah"), 1, 0))
    solve = ["solve", "t.json", "--scheduler", "tcp://127.0.0.1:1", "--json", "out.json"]
    done = _blocked(
        ["dask", "distributed"],
        f"from sahgrasp.cli import main; sys.exit(main({solve!r}))",
        tmp_path,
    )
    _one_line(done, r'tcp://127\.0\.0\.1:1 needs Dask: pip install "sahgrasp\[cluster\]"')
    assert not (tmp_path / "out.json").exists()


def test_a_plot_without_matplotlib_is_one_line_naming_the_plot_extra(tmp_path: Path) -> None:
    atlas = ["atlas", "planar", "--plot", "f.png"]
    done = _blocked(
        ["matplotlib"], f"from sahgrasp.cli import main; sys.exit(main({atlas!r}))", tmp_path
    )
    _one_line(done, r'--plot f\.png needs matplotlib: pip install "sahgrasp\[plot\]"')
    assert not (tmp_path / "f.png").exists()


@pytest.mark.slow
def test_the_scenes_colour_quality_without_matplotlib(tmp_path: Path) -> None:
    code = (
        "from sahgrasp.viz.colors import quality_colors\n"
        "print(quality_colors([0.0, 0.5, 1.0, -1.0], 0.0).round(4).tolist())\n"
        "print('matplotlib' in sys.modules and sys.modules['matplotlib'] is not None)\n"
    )
    done = _blocked(["matplotlib"], code, tmp_path)
    assert done.returncode == 0, done.stderr
    colors, loaded = done.stdout.strip().splitlines()
    from sahgrasp.viz.colors import quality_colors

    assert colors == str(quality_colors([0.0, 0.5, 1.0, -1.0], 0.0).round(4).tolist())
    assert loaded == "False"


# The install command follows how sahgrasp was installed.
class _Dist:
    def __init__(self, direct_url: str | None) -> None:
        self.direct_url = direct_url

    def read_text(self, name: str) -> str | None:
        return self.direct_url if name == "direct_url.json" else None


@pytest.mark.parametrize(
    ("direct_url", "editable"),
    [
        ('{"dir_info": {"editable": true}, "url": "file:///src/sahgrasp"}', True),
        ('{"dir_info": {}, "url": "file:///src/sahgrasp"}', False),  # pip install .
        (None, False),  # from the package index: no direct_url.json
        ("not json", False),
    ],
)
def test_editable_installs_are_told_apart(
    monkeypatch: pytest.MonkeyPatch, direct_url: str | None, editable: bool
) -> None:
    monkeypatch.setattr(metadata, "distribution", lambda name: _Dist(direct_url))
    assert is_editable_install() is editable
    expected = 'pip install -e ".[bench]"' if editable else 'pip install "sahgrasp[bench]"'
    assert install_command("bench") == expected


def test_a_source_folder_without_install_counts_as_a_checkout(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    def missing(name: str) -> Any:
        raise metadata.PackageNotFoundError(name)

    monkeypatch.setattr(metadata, "distribution", missing)
    assert install_command("sim") == 'pip install -e ".[sim]"'


def test_the_bench_peers_say_the_command_that_fits(monkeypatch: pytest.MonkeyPatch) -> None:
    from sahgrasp.bench import peers

    monkeypatch.setattr(metadata, "distribution", lambda name: _Dist(None))
    monkeypatch.setattr(peers, "_missing_module", lambda modules: modules[0])
    skipped = peers.available_peers(["pink"])[1]
    assert 'install it with pip install "sahgrasp[bench]"' in skipped["pink"]
