"""The old module paths import, warn and are the new modules; the repository uses none of them."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

from sahgrasp._moved import BECAME_PACKAGES, MOVED, MOVED_NAMES, MovedModuleFinder

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(("old", "new"), sorted(MOVED.items()))
def test_an_old_path_warns_and_is_the_new_module(
    old: str, new: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.delitem(sys.modules, old, raising=False)
    with pytest.warns(DeprecationWarning, match=re.escape(new)):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    assert sys.modules[old] is module


@pytest.mark.parametrize(("package", "module"), sorted(BECAME_PACKAGES.items()))
def test_an_old_module_that_became_a_package_keeps_its_names(package: str, module: str) -> None:
    old_contents = importlib.import_module(module)
    new_package = importlib.import_module(package)
    for name in old_contents.__all__:
        assert getattr(new_package, name) is getattr(old_contents, name), name
    assert set(old_contents.__all__) <= set(new_package.__all__)


_NAMES = sorted(
    (module, name, new)
    for module, names in MOVED_NAMES.items()
    for name, new in names.items()
    if "." not in name
)


@pytest.mark.parametrize(("module", "name", "new"), _NAMES)
def test_a_moved_name_warns_and_is_the_new_object(module: str, name: str, new: str) -> None:
    new_module, new_name = new.split(":")
    with pytest.warns(DeprecationWarning, match=re.escape(f"{new_module}.{new_name}")):
        value = getattr(importlib.import_module(module), name)
    assert value is getattr(importlib.import_module(new_module), new_name)
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        _ = importlib.import_module(module).nothing


def test_the_moved_methods_warn_and_answer_as_their_new_functions(tmp_path: Path) -> None:
    from sahgrasp.model.contacts import GraspTarget, ObjectSpec

    data = {
        "name": "g",
        "contacts": [{"finger": "thumb", "point": [0, 0, 0], "normal": [0, 0, 1]}],
        "object": {"name": "can"},
    }
    with pytest.warns(DeprecationWarning, match="problem_from_dict"):
        target = GraspTarget.from_dict(data, tmp_path)
    assert target.object_spec == ObjectSpec(name="can", mesh=None)
    with pytest.warns(DeprecationWarning, match="build_object"):
        assert target.object_spec.load().name == "can"


def test_the_finder_answers_only_old_names() -> None:
    finder = MovedModuleFinder()
    assert finder.find_spec("sahgrasp.model.hand") is None
    assert finder.find_spec("sahgrasp.nothing") is None
    spec = finder.find_spec("sahgrasp.hand")
    assert spec is not None and spec.name == "sahgrasp.hand"
    import sahgrasp  # noqa: F401  (installs the finder once, however often imported)

    assert sum(isinstance(f, MovedModuleFinder) for f in sys.meta_path) == 1


@pytest.mark.parametrize("module", ["sahgrasp", "sahgrasp.quality", "sahgrasp.quality.indices"])
def test_light_imports_stay_numpy_free(module: str) -> None:
    code = f"import sys, {module}; print('numpy' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# An old dotted name as code or docs would write it: not followed by more of a name, and for the
# old modules that are packages now, only their re-exports are legitimate.
_OLD = re.compile(
    r"(?<![\w.])(" + "|".join(re.escape(o) for o in sorted(MOVED, key=len, reverse=True)) + r")"
    r"(?!\w)"
)
_FROM = re.compile(r"^\s*from sahgrasp import ([^\n(]+)$", re.MULTILINE)
_OLD_LEAVES = {old.removeprefix("sahgrasp.") for old in MOVED if old.count(".") == 1}


def _repository_files() -> list[Path]:
    found = [
        *ROOT.joinpath("sahgrasp").rglob("*.py"),
        *ROOT.joinpath("tests").rglob("*.py"),
        *ROOT.joinpath("benchmarks").rglob("*.py"),
        *ROOT.joinpath("tools").rglob("*.py"),
        *ROOT.joinpath("examples").rglob("*.py"),
        *ROOT.joinpath("docs").rglob("*.md"),
        ROOT / "mkdocs.yml",
        ROOT / "pyproject.toml",
        ROOT / "setup.py",
    ]
    skip = {ROOT / "sahgrasp" / "_moved.py", Path(__file__).resolve()}
    return sorted(p for p in found if p.is_file() and p.resolve() not in skip)


def old_paths(text: str) -> list[str]:
    """The old module names ``text`` uses (dotted, or imported ``from sahgrasp``)."""
    used = [m.group(1) for m in _OLD.finditer(text)]
    for match in _FROM.finditer(text):
        names = {item.split(" as ")[0].strip() for item in match.group(1).split(",")}
        used += sorted(f"sahgrasp.{name}" for name in names & _OLD_LEAVES)
    return used


def test_the_checker_sees_old_paths() -> None:
    assert old_paths("from sahgrasp.hand import Hand") == ["sahgrasp.hand"]
    assert old_paths("x = 'sahgrasp.objects.frames.placement'") == ["sahgrasp.objects.frames"]
    assert old_paths("from sahgrasp import fileio, ik") == ["sahgrasp.fileio"]
    assert old_paths("from sahgrasp.model.hand import Hand\nimport sahgrasp.hand_checks2") == []
    assert old_paths("from sahgrasp.quality import Manipulability") == []


def test_no_code_of_the_repository_uses_an_old_path() -> None:
    found = [
        f"{path.relative_to(ROOT)}: {name}"
        for path in _repository_files()
        for name in old_paths(path.read_text(encoding="utf-8"))
    ]
    assert not found, "\n".join(found)
