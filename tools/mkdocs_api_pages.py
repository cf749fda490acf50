"""MkDocs hook: the nav follows the package and the docs folder, found on disk at build time.

Every top-level module and package of ``sahgrasp/`` except the entry points (``cli``, ``bench``)
and private names gets a page ``api/<module>.md`` holding ``::: sahgrasp.<module>``, listed under
the nav's "API reference" after the hand-written ``api/sahgrasp.md``. A page that mkdocs.yml does
not list is appended to the nav section of its folder (``docs/tutorials/`` to "Tutorials",
``docs/how-to/`` to "How-to", ``docs/methods/`` to "Methods", ``docs/*.md`` to "Develop") under its
own first heading. So a module or a page added by a change is published without editing
mkdocs.yml. Loaded by mkdocs.yml
(``hooks:``).
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.structure.files import File, Files

PACKAGE = Path(__file__).resolve().parents[1] / "sahgrasp"
ENTRY_POINTS = frozenset({"cli", "bench"})
SECTION = "API reference"
SECTIONS = {"tutorials": "Tutorials", "how-to": "How-to", "methods": "Methods", "": "Develop"}
"""The nav section of each docs folder (``""``: the docs folder itself) for unlisted pages."""


def library_modules() -> list[str]:
    """Top-level public modules and packages of the library, sorted."""
    names = {
        path.name.removesuffix(".py")
        for path in PACKAGE.iterdir()
        if path.suffix == ".py" or (path / "__init__.py").is_file()
    }
    return sorted(n for n in names if not n.startswith("_") and n not in ENTRY_POINTS)


def _section(config: MkDocsConfig, title: str) -> list[object]:
    for entry in config.nav or []:
        if isinstance(entry, dict) and title in entry:
            pages: list[object] = entry[title]
            return pages
    raise ValueError(f"mkdocs.yml: the nav has no {title!r} section")


def _listed(nav: object) -> set[str]:
    """Every page path that a nav (list, mapping or path) names."""
    if isinstance(nav, str):
        return {nav}
    children = nav.values() if isinstance(nav, dict) else nav if isinstance(nav, list) else []
    return set().union(*(_listed(child) for child in children))


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    """Fill the API reference with one page per module; append unlisted pages to their section."""
    api = _section(config, SECTION)
    api[:] = [{"sahgrasp": "api/sahgrasp.md"}]
    api += [{module: f"api/{module}.md"} for module in library_modules()]
    listed = _listed(config.nav)
    docs = Path(config.docs_dir)
    for folder, title in SECTIONS.items():
        pages = sorted(p.relative_to(docs).as_posix() for p in (docs / folder).glob("*.md"))
        _section(config, title).extend(page for page in pages if page not in listed)
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    """Add the generated module pages to the site's files."""
    for module in library_modules():
        content = f"::: sahgrasp.{module}\n"
        files.append(File.generated(config, f"api/{module}.md", content=content))
    return files
