"""Every module's imports obey the layering table of docs/architecture.md.

The table is parsed from the markdown, so the document and the test cannot disagree. Imports are
read from each file's syntax tree: module level, inside functions and under ``TYPE_CHECKING``.
A module may import its own layer and the layers of smaller rank, never a larger rank; only the
layers marked ``yes`` may import ``argparse``.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "sahgrasp"
ARCHITECTURE = ROOT / "docs" / "architecture.md"
HEADER = ["rank", "layer", "modules", "argparse"]


@dataclass(frozen=True)
class Layer:
    rank: int
    name: str
    argparse: bool


@dataclass(frozen=True)
class Edge:
    """One import in ``path`` at ``line`` of the sahgrasp module ``target`` (or ``argparse``)."""

    path: Path
    line: int
    target: str
    in_function: bool = False

    def __str__(self) -> str:
        return f"{self.path.relative_to(ROOT)}:{self.line} imports {self.target}"


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in row.strip().strip("|").split("|")]


@cache
def layers() -> dict[str, Layer]:
    """Module name -> its layer, from the table whose header is HEADER."""
    rows = iter(ARCHITECTURE.read_text(encoding="utf-8").splitlines())
    for row in rows:
        if row.startswith("|") and _cells(row) == HEADER:
            break
    else:
        raise AssertionError(f"{ARCHITECTURE}: no table with the header {HEADER}")
    next(rows)  # the |---| separator
    table: dict[str, Layer] = {}
    for row in rows:
        if not row.startswith("|"):
            break
        rank, name, modules, argparse = _cells(row)
        assert argparse in {"yes", "no"}, f"argparse column must be yes or no: {row}"
        layer = Layer(int(rank), name, argparse == "yes")
        for module in re.findall(r"`([^`]+)`", modules):
            assert module not in table, f"{module} is in two layers"
            table[module] = layer
    return table


def module_of(path: Path, package: Path = PACKAGE) -> str:
    """``sahgrasp/ik/solver.py`` -> ``ik``; the package's own ``__init__.py`` -> ``__init__``."""
    parts = path.relative_to(package).parts
    return parts[0].removesuffix(".py")


def _package_parts(path: Path, package: Path = PACKAGE) -> list[str]:
    """Dotted-name parts of the package that holds ``path`` (for relative imports)."""
    return ["sahgrasp", *path.parent.relative_to(package).parts]


def _imported_names(
    node: ast.Import | ast.ImportFrom, path: Path, package: Path = PACKAGE
) -> Iterator[tuple[str, str]]:
    """(absolute module, imported name) pairs; the name is "" for ``import a.b``."""
    if isinstance(node, ast.Import):
        yield from ((alias.name, "") for alias in node.names)
        return
    parts = _package_parts(path, package)
    base = parts[: len(parts) - node.level + 1] if node.level else []
    module = ".".join([*base, *([node.module] if node.module else [])])
    yield from ((module, alias.name) for alias in node.names)


def _target(module: str, name: str, package: Path = PACKAGE) -> str | None:
    """The layering-table name of an import, or None when it is neither ours nor argparse."""
    parts = module.split(".")
    if parts[0] == "argparse":
        return "argparse"
    if parts[0] != "sahgrasp":
        return None
    if len(parts) > 1:
        return parts[1]
    # ``from sahgrasp import ik`` loads a module, ``from sahgrasp import load_hand`` a re-export.
    is_module = (package / name).is_dir() or (package / f"{name}.py").is_file()
    return name if is_module else "__init__"


def edges(path: Path, source: str | None = None, package: Path = PACKAGE) -> Iterator[Edge]:
    """Imports of sahgrasp modules and of argparse in ``path`` (or in ``source``, as if there)."""
    text = path.read_text(encoding="utf-8") if source is None else source
    tree = ast.parse(text, str(path))
    in_functions = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
        for inner in ast.walk(node)
    }
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            for module, name in _imported_names(node, path, package):
                target = _target(module, name, package)
                if target is not None:
                    yield Edge(path, node.lineno, target, id(node) in in_functions)


def sources(package: Path = PACKAGE) -> list[Path]:
    return sorted(package.rglob("*.py"))


def broken_rules(path: Path, found: Iterable[Edge]) -> Iterator[str]:
    """The imports among ``found`` that ``path``'s layer may not make, explained."""
    table = layers()
    own = table.get(module_of(path))
    if own is None:  # reported by test_every_module_has_a_layer
        return
    for edge in found:
        if edge.target == "argparse":
            if not own.argparse:
                yield f"{edge}: the {own.name} layer may not parse arguments"
            continue
        used = table.get(edge.target)
        if used is not None and used.rank > own.rank:
            yield f"{edge}: {own.name} (rank {own.rank}) may not use {used.name}"


def package_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Package -> the other packages it imports (module level, in functions, for type checking)."""
    graph: dict[str, set[str]] = {}
    for path in sources(package):
        own = module_of(path, package)
        used = graph.setdefault(own, set())
        used |= {
            e.target for e in edges(path, package=package) if e.target not in {own, "argparse"}
        }
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        for other in sorted(graph.get(node, ())):
            if other not in index:
                visit(other)
                low[node] = min(low[node], low[other])
            elif other in stack:
                low[node] = min(low[node], index[other])
        if low[node] == index[node]:
            component = []
            while (member := stack.pop()) != node:
                component.append(member)
            component.append(node)
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return sorted(found)


def test_the_table_is_complete_and_ordered() -> None:
    table = layers()
    assert sorted({layer.rank for layer in table.values()}) == list(range(7))
    for must in ("core", "atlas", "model", "ik", "viz", "experiments", "cli", "bench"):
        assert must in table
    assert table["core"].rank < table["atlas"].rank < table["model"].rank < table["ik"].rank
    assert table["ik"].rank < table["viz"].rank < table["experiments"].rank < table["cli"].rank


def test_every_module_has_a_layer() -> None:
    missing = {module_of(p) for p in sources()} - layers().keys()
    assert not missing, f"modules without a row in {ARCHITECTURE.name}: {sorted(missing)}"


def test_every_import_of_a_sahgrasp_module_names_a_module_with_a_layer() -> None:
    known = layers().keys() | {"argparse"}
    unknown = [str(e) for p in sources() for e in edges(p) if e.target not in known]
    assert not unknown, "\n".join(unknown)


def test_imports_point_down_the_layers() -> None:
    found = [rule for path in sources() for rule in broken_rules(path, edges(path))]
    assert not found, f"{len(found)} layering violations:\n" + "\n".join(found)


def test_the_reader_sees_function_level_relative_and_package_imports() -> None:
    source = (
        "import argparse\n"
        "from sahgrasp import load_hand, model\n"
        "def f():\n"
        "    from ..viz import show\n"
        "    import sahgrasp.experiments.paper\n"
        "    from . import solver\n"
    )
    path = PACKAGE / "ik" / "_probe.py"  # never written: only its package matters
    nodes = [n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.Import | ast.ImportFrom)]
    pairs = [pair for node in nodes for pair in _imported_names(node, path)]
    assert [_target(*pair) for pair in pairs] == [
        "argparse",
        "__init__",
        "model",
        "viz",
        "experiments",
        "ik",
    ]


@pytest.mark.parametrize(
    ("where", "source", "broken"),
    [
        (
            "atlas/builder.py",
            "from sahgrasp.model.hand import Hand\n",
            ["engine (rank 1) may not use model"],
        ),
        (
            "viz/x.py",
            "def f():\n    from sahgrasp.experiments import t\n",
            ["may not use experiments"],
        ),
        ("model/hand.py", "import argparse\n", ["the model layer may not parse arguments"]),
        ("ik/x.py", "from ..cli import main\n", ["solvers (rank 3) may not use entry points"]),
        ("cli/x.py", "import argparse\nfrom sahgrasp.experiments import t\n", []),
        ("objects/x.py", "from sahgrasp.core.errors import SahGraspError\nimport numpy\n", []),
    ],
)
def test_the_rules_catch_upward_imports_and_argparse(
    where: str, source: str, broken: list[str]
) -> None:
    path = PACKAGE / where  # never written: the source is given
    found = list(broken_rules(path, edges(path, source)))
    assert len(found) == len(broken)
    for message, expected in zip(found, broken, strict=True):
        assert expected in message


def test_no_import_cycles_between_packages() -> None:
    found = cycles(package_graph())
    assert found == [], f"packages that import each other: {found}"


def _write(root: Path, files: dict[str, str]) -> Path:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text, encoding="utf-8")
    return root


def test_the_cycle_check_finds_a_planted_cycle(tmp_path: Path) -> None:
    package = _write(
        tmp_path / "sahgrasp",
        {
            "__init__.py": "",
            "core/__init__.py": "",
            "core/errors.py": "",
            "model/__init__.py": "",
            "model/hand.py": "from sahgrasp.core.errors import E\n",
            "objects/__init__.py": "from sahgrasp.model.hand import Hand\n",
            "objects/body.py": "def f():\n    from ..model import hand\n",
        },
    )
    assert cycles(package_graph(package)) == []
    (package / "model" / "contacts.py").write_text(
        "if TYPE_CHECKING:\n    from sahgrasp.objects.body import Body\n", encoding="utf-8"
    )
    assert cycles(package_graph(package)) == [["model", "objects"]]
    (package / "core" / "fileio.py").write_text("import sahgrasp.objects\n", encoding="utf-8")
    assert cycles(package_graph(package)) == [["core", "model", "objects"]]


# Function-level imports of sahgrasp modules hide a dependency (and so a cycle) from the reader.
# The command line loads its commands' libraries lazily on purpose (``--help`` stays fast), and
# so do the benchmarks' entry points; the package ``__init__``s load names through ``__getattr__``
# (importlib, not an import statement). Everywhere else an import of ours is at module level.
LAZY_PACKAGES = ("cli", "bench")
FUNCTION_LEVEL_ALLOWED = {
    # Every command's parser imports the shared options at --help time; turning them into the
    # IK's settings needs the IK (Pinocchio), loaded only when a command runs.
    "experiments/arguments.py": "ik",
}


def function_level_imports(path: Path, source: str | None = None) -> list[Edge]:
    """The function-level imports of sahgrasp modules in ``path`` that no rule allows."""
    where = path.relative_to(PACKAGE).as_posix()
    if where.split("/")[0] in LAZY_PACKAGES:
        return []
    found = [e for e in edges(path, source) if e.in_function and e.target != "argparse"]
    return [e for e in found if FUNCTION_LEVEL_ALLOWED.get(where) != e.target]


def test_imports_of_sahgrasp_modules_are_at_module_level() -> None:
    found = [str(edge) for path in sources() for edge in function_level_imports(path)]
    assert not found, "function-level imports of sahgrasp modules:\n" + "\n".join(found)


def test_every_allowed_function_level_import_is_still_there() -> None:
    for where, target in FUNCTION_LEVEL_ALLOWED.items():
        path = PACKAGE / where
        assert any(e.in_function and e.target == target for e in edges(path)), where


@pytest.mark.parametrize(
    ("where", "source", "flagged"),
    [
        ("ik/x.py", "def f():\n    from sahgrasp.objects import GraspObject\n", ["objects"]),
        ("ik/x.py", "class A:\n    def f(self):\n        from ..core import fileio\n", ["core"]),
        ("ik/x.py", "def f():\n    import trimesh\n", []),
        ("ik/x.py", "from sahgrasp.objects import GraspObject\n", []),
        ("cli/x.py", "def run():\n    from sahgrasp.ik import solve_ik\n", []),
        ("bench/x.py", "def run():\n    from sahgrasp.planner import plan_grasps\n", []),
        (
            "model/contacts.py",
            "def f():\n    from sahgrasp.objects import load_mesh\n",
            ["objects"],
        ),
        ("experiments/arguments.py", "def f():\n    from sahgrasp.ik import solve_ik\n", []),
        ("experiments/arguments.py", "def f():\n    from sahgrasp.objects import x\n", ["objects"]),
    ],
)
def test_the_rule_sees_function_level_imports(where: str, source: str, flagged: list[str]) -> None:
    found = function_level_imports(PACKAGE / where, source)
    assert [edge.target for edge in found] == flagged
