"""The experiments layer: library modules do not import it, its options and defaults agree."""

from __future__ import annotations

import argparse
import ast
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
from sahgrasp.quality import INDICES

ROOT = Path(__file__).resolve().parent.parent
LIBRARY = ("hand", "contacts", "ik", "sequence", "atlas", "quality", "grasp", "planar",
           "optimization", "motions", "objects", "viz", "progress", "errors")  # fmt: skip


SCRIPTS = {"viz/meshcat_server.py", "viz/screenshot.py"}
"""Library files that are also command-line programs (argparse allowed, nothing else of ours)."""


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at any depth (lazy imports in functions included)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module is not None:
            names.add(node.module)
    return names


def library_files() -> list[Path]:
    package = ROOT / "sahgrasp"
    files = []
    for name in LIBRARY:
        single = package / f"{name}.py"
        files.extend([single] if single.is_file() else sorted((package / name).rglob("*.py")))
    return files


@pytest.mark.parametrize("path", library_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_library_modules_import_neither_experiments_nor_argparse(path: Path) -> None:
    imports = imported_modules(path)
    assert not {m for m in imports if m.startswith("sahgrasp.experiments")}
    if str(path.relative_to(ROOT / "sahgrasp")) not in SCRIPTS:
        assert "argparse" not in imports
    assert not {m for m in imports if m.startswith("sahgrasp.cli")}


def test_nothing_imports_the_cli_but_the_cli() -> None:
    for path in (ROOT / "sahgrasp").rglob("*.py"):
        # python -m sahgrasp runs the CLI
        if "cli" not in path.relative_to(ROOT).parts and path.name != "__main__.py":
            assert not {m for m in imported_modules(path) if m.startswith("sahgrasp.cli")}, path


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
