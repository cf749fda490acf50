"""Dependency hygiene: what the library imports is what pyproject.toml declares, and no more.

Every third-party module imported anywhere in ``sahgrasp/`` (module or function level, read from the
AST) must come from a declared runtime dependency; the benchmarks (``sahgrasp/bench``) may also use
the ``bench`` extra. Every declared runtime dependency must be used. Test-only packages stay out of
the library. Importing the package and printing ``sahgrasp --help`` must not load the heavy optional
layers (plotting, the viewer, Dask, mesh files).
"""

from __future__ import annotations

import ast
import importlib.metadata
import json
import os
import re
import subprocess
import sys
from collections.abc import Iterator
from functools import cache
from pathlib import Path
from typing import Any

import pytest

tomllib = pytest.importorskip("tomllib")  # Python >= 3.11; the project's CI runs 3.11

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sahgrasp"
BENCH = PACKAGE / "bench"
SIM = PACKAGE / "sim"

# Loaded only when a command or function that needs them runs.
LAZY = ("matplotlib", "meshcat", "dask", "trimesh", "pinocchio.visualize", "mujoco")

# Declared runtime dependencies that sahgrasp never imports itself: trimesh imports them, only
# when the mesh path needs them (trimesh declares neither in its base requirements).
BACKENDS = {"rtree": "trimesh's ray and bounds-tree code", "networkx": "trimesh.repair"}


def _normalize(name: str) -> str:
    """PEP 503 name: lower case, runs of ``-_.`` as one ``-``."""
    return re.sub(r"[-_.]+", "-", name).lower()


def _requirement_name(requirement: str) -> str:
    """Distribution name of a PEP 508 requirement string (``dask[distributed]>=1`` -> ``dask``)."""
    match = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)", requirement)
    assert match, f"unparsable requirement {requirement!r} in pyproject.toml"
    return _normalize(match.group(1))


@cache
def _project() -> dict[str, Any]:
    with (ROOT / "pyproject.toml").open("rb") as f:
        project: dict[str, Any] = tomllib.load(f)["project"]
    return project


def _runtime() -> set[str]:
    return {_requirement_name(r) for r in _project()["dependencies"]}


def _extra(name: str) -> set[str]:
    return {_requirement_name(r) for r in _project()["optional-dependencies"][name]}


def _sources() -> Iterator[Path]:
    yield from sorted(PACKAGE.rglob("*.py"))


def _third_party_imports(path: Path) -> Iterator[tuple[str, int]]:
    """(top-level module, line) of every absolute import of a non-stdlib, non-sahgrasp module."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        else:
            continue
        for name in names:
            top = name.split(".")[0]
            if top != "sahgrasp" and top not in sys.stdlib_module_names:
                yield top, node.lineno


def _distribution_lookups(path: Path) -> Iterator[str]:
    """Names passed as literals to ``metadata.distribution(...)`` (data-only packages)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute | ast.Name)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "distribution"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            yield _normalize(node.args[0].value)


@cache
def _module_distributions() -> dict[str, frozenset[str]]:
    """Top-level import name -> the installed distributions that provide it.

    ``packages_distributions`` misses the cmeel wheels (pin, coal), which install under
    ``cmeel.prefix/lib/pythonX.Y/site-packages``; their file lists name the module there.
    """
    found: dict[str, set[str]] = {
        module: {_normalize(d) for d in dists}
        for module, dists in importlib.metadata.packages_distributions().items()
    }
    for dist in importlib.metadata.distributions():
        for file in dist.files or ():
            parts = file.parts
            if "site-packages" in parts[:-1]:
                top = parts[parts.index("site-packages") + 1].split(".")[0]
                found.setdefault(top, set()).add(_normalize(dist.metadata["Name"]))
    return {module: frozenset(dists) for module, dists in found.items()}


def _providers(module: str) -> frozenset[str]:
    return _module_distributions().get(module, frozenset())


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.distribution(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


@pytest.mark.slow
def test_every_library_import_is_a_declared_runtime_dependency() -> None:
    runtime, bench = _runtime(), _extra("bench")
    # Without the bench extra installed (CI installs dev and docs only), its modules cannot be
    # mapped to distributions; the benchmarks import them inside functions, behind a check.
    bench_installed = all(_installed(d) for d in bench)
    undeclared = []
    for path in _sources():
        in_bench = BENCH in path.parents
        allowed = runtime | bench if in_bench else runtime
        if SIM in path.parents:  # sahgrasp.sim is the optional extra "sim"
            allowed = allowed | _extra("sim")
        allowed = allowed | _extra("cluster") | _extra("plot")  # in functions, behind a check
        for module, line in _third_party_imports(path):
            providers = _providers(module)
            if not providers and in_bench and not bench_installed:
                continue
            if not providers & allowed:
                rel = path.relative_to(ROOT)
                undeclared.append(f"{rel}:{line} imports {module} (from {sorted(providers)})")
    assert not undeclared, "undeclared runtime dependencies:\n" + "\n".join(undeclared)


@pytest.mark.slow
def test_every_runtime_dependency_is_used_by_the_library() -> None:
    used: set[str] = set(BACKENDS)
    for path in _sources():
        used.update(_distribution_lookups(path))
        for module, _ in _third_party_imports(path):
            used |= _providers(module)
    assert _runtime() - used == set(), "declared but never imported by sahgrasp/"


@pytest.mark.parametrize("dev_only", ["hypothesis", "yourdfpy", "pytest", "psutil"])
def test_test_only_packages_are_not_runtime_dependencies(dev_only: str) -> None:
    assert dev_only in _extra("dev")
    assert dev_only not in _runtime()


def test_the_library_imports_no_test_only_package() -> None:
    optional = _extra("bench") | _extra("sim") | _extra("cluster") | _extra("plot")
    test_only = _extra("dev") - _runtime() - optional
    offenders = [
        f"{path.relative_to(ROOT)}:{line} imports {module}"
        for path in _sources()
        for module, line in _third_party_imports(path)
        if _providers(module) & test_only
    ]
    assert not offenders, "\n".join(offenders)


def test_the_extras_are_in_dev_and_all_and_not_runtime() -> None:
    for extra in ("cluster", "plot", "sim"):
        assert _extra(extra) <= _extra("dev") & _extra("all") - _runtime(), extra


def test_the_cluster_and_plot_extras_are_imported_only_in_functions() -> None:
    """Outside functions, an import of Dask or matplotlib would break ``pip install .``."""
    optional = _extra("cluster") | _extra("plot")
    found = []
    for path in _sources():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        for node in tree.body:  # module level, including under if/try
            for inner in ast.walk(node):
                if isinstance(inner, ast.FunctionDef | ast.AsyncFunctionDef):
                    break
                if isinstance(inner, ast.Import | ast.ImportFrom):
                    names = (
                        [a.name for a in inner.names]
                        if isinstance(inner, ast.Import)
                        else [inner.module or ""]
                    )
                    if any(_providers(n.split(".")[0]) & optional for n in names):
                        found.append(f"{path.relative_to(ROOT)}:{inner.lineno}")
    assert not found, "module-level imports of an optional extra:\n" + "\n".join(found)


def _loaded_after(code: str) -> list[str]:
    """Which of LAZY a fresh interpreter has in sys.modules after running ``code``."""
    report = f"import sys, json; print(json.dumps([m for m in {LAZY!r} if m in sys.modules]))"
    script = f"{code}\n{report}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120
    )
    assert out.returncode == 0, out.stderr
    loaded = json.loads(out.stdout.strip().splitlines()[-1])
    assert isinstance(loaded, list)
    return loaded


def test_import_sahgrasp_loads_no_optional_layer() -> None:
    assert _loaded_after("import sahgrasp") == []


def test_cli_help_loads_no_optional_layer() -> None:
    code = (
        "import contextlib, io\n"
        "from sahgrasp.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "    main(['--help'])"
    )
    assert _loaded_after(code) == []


def test_the_mesh_path_back_ends_are_declared_and_used(tmp_path: Path) -> None:
    """A mesh that needs repairs, then a ray query: trimesh loads its back-ends, all declared.

    ``pip install .`` alone must handle meshes: a back-end that trimesh imports here and that
    pyproject.toml does not declare is missing on a fresh machine (ModuleNotFoundError). trimesh
    also imports whatever optional module happens to be installed (embreex, shapely...), so only
    a fresh install proves that nothing else is needed: CI's install-only stage (.ci/run).
    """
    assert set(BACKENDS) <= _runtime()
    code = f"""
import numpy as np, trimesh
from sahgrasp.objects import load_mesh
box = trimesh.creation.box((0.06, 0.06, 0.08))
faces = box.faces[1:].copy()
faces[0] = faces[0][::-1]  # a hole and a flipped triangle: both repaired on loading
trimesh.Trimesh(box.vertices, faces, process=False).export({str(tmp_path / "b.stl")!r})
solid = load_mesh({str(tmp_path / "b.stl")!r}).solids[0]
assert solid.repairs, solid.repairs
solid.trimesh.ray.intersects_location(np.zeros((1, 3)), [[1.0, 0.0, 0.0]])
"""
    report = "import sys, json; print(json.dumps(sorted(m for m in sys.modules if '.' not in m)))"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", f"{code}\n{report}"], env=env, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    loaded = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert set(BACKENDS) <= loaded, f"not loaded by the mesh path: {set(BACKENDS) - loaded}"
