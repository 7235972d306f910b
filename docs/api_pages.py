"""The API reference's pages, written from the packages themselves.

Every name of ``piezohyst.__all__`` and of each subpackage face's ``__all__`` gets a page
(autosummary), grouped by topic as the package's own docstring groups it: a docstring line
indented under a heading that lists names (``Compensator, CompensatorState -- ...``) puts
those names under that heading. A name the docstring does not list goes under "More names";
an object documented on an earlier face is linked there, not documented twice.
"""

from __future__ import annotations

import importlib
import inspect
import re
import shutil
from pathlib import Path

#: the faces, in the order their pages appear; an object gets its page on the first
FACES = [
    ("piezohyst", "The package: what ``import piezohyst as ph`` gives"),
    ("piezohyst.model", "Models, calibrations, files and banks"),
    ("piezohyst.model.terms", "Growth and shape terms"),
    ("piezohyst.control", "Compensators, controllers, learning"),
    ("piezohyst.control.export", "The compensator outside Python: C, shared library, MEX, FMU"),
    ("piezohyst.analysis", "Comparing and choosing models"),
    ("piezohyst.analysis.selection", "The model choice's parts"),
    ("piezohyst.simulation", "The simulated bench, plants and stage"),
    ("piezohyst.io", "Reading and writing records"),
    ("piezohyst.io.screening", "A record's screen: glitches and gaps"),
    ("piezohyst.workflows", "File to file: what the command line runs"),
    ("piezohyst.metrics", "Error measures"),
    ("piezohyst.units", "Units"),
    ("piezohyst.plotting", "Figures"),
    ("piezohyst.errors", "Errors and warnings"),
    ("piezohyst.testing", "Checking a core of your own"),
]

SOURCES = Path(__file__).resolve().parents[1] / "src" / "piezohyst"
_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def topics(module_name: str) -> list[tuple[str, list[str]]]:
    """The docstring's map: (heading, names) in order, then the names it does not list."""
    module = importlib.import_module(module_name)
    public = list(getattr(module, "__all__", []))
    doc = inspect.getdoc(module) or ""
    groups: list[tuple[str, list[str]]] = []
    heading: list[str] = []
    placed: set[str] = set()
    borders = 0
    for line in doc.splitlines():
        if line.startswith("=="):  # a simple table: module | its names; the first row heads it
            borders += 1
            heading = []
            continue
        if borders in (2, 3) and line.strip():
            first = line.split()[0] if not line.startswith(" ") else ""
            if first:
                heading = [f"{module_name}.{first.strip('`')}"]
            names = [
                n for n in _NAME.findall(line[len(first) :]) if n in public and n not in placed
            ]
            if names:
                if not groups or groups[-1][0] != heading[0]:
                    groups.append((heading[0], []))
                groups[-1][1].extend(names)
                placed.update(names)
            continue
        if not line.strip():
            heading = []
            continue
        if line.startswith("    ") and heading:
            listed = line.split(" -- ")[0]
            names = [n for n in _NAME.findall(listed) if n in public and n not in placed]
            if not names:
                continue
            title = " ".join(heading)
            if not groups or groups[-1][0] != title:
                groups.append((title, []))
            groups[-1][1].extend(names)
            placed.update(names)
        elif not line.startswith(" "):
            if groups and groups[-1][0] == " ".join(heading):
                heading = []
            heading.append(line.strip())
    rest = [n for n in public if n not in placed and not n.startswith("_")]
    if rest:
        groups.append(("More names" if groups else "Names", rest))
    return groups


def _title(text: str) -> str:
    """A heading from a docstring's heading line: its notes dropped, its RST made plain."""
    depth, kept = 0, []
    for char in text:  # parenthesised notes dropped, nested ones too
        depth += char == "("
        if depth == 0:
            kept.append(char)
        depth -= char == ")" and depth > 0
    text = re.sub(r"\s+", " ", "".join(kept).replace("``", "")).strip().rstrip(":,")
    if text.startswith("piezohyst."):
        return text  # a module's name keeps its case
    return text[:1].upper() + text[1:] if text else "Names"


def _comment(name: str) -> str:
    """The ``#:`` comment above ``name``'s assignment in piezohyst's sources ("" if none)."""
    pattern = re.compile(rf"((?:^#:.*\n)+)^{re.escape(name)}\s*[:=]", re.MULTILINE)
    for path in sorted(SOURCES.rglob("*.py")):
        found = pattern.search(path.read_text())
        if found:
            return " ".join(line[2:].strip() for line in found.group(1).splitlines())
    return ""


def _intro(module_name: str) -> list[str]:
    """The package docstring's first paragraph (its map is the page's sections)."""
    doc = inspect.getdoc(importlib.import_module(module_name)) or ""
    return [*doc.split("\n\n")[0].splitlines(), ""]


def _data(name: str, value: object) -> list[str]:
    """A constant or a type alias: its value and its ``#:`` comment."""
    shown = " ".join(repr(value).split())
    shown = shown if len(shown) <= 200 else shown[:197] + "..."
    return [f".. py:data:: {name}", f"   :value: {shown}", "", f"   {_comment(name)}", ""]


def _page(module_name: str, blurb: str, owner: dict[int, str]) -> str:
    module = importlib.import_module(module_name)
    lines = [module_name, "=" * len(module_name), "", blurb + ".", "", *_intro(module_name),
             f".. py:module:: {module_name}", "   :no-index:", "",
             f".. currentmodule:: {module_name}", ""]  # fmt: skip
    elsewhere: list[str] = []
    constants: list[str] = []
    for heading, names in topics(module_name):
        own = []
        for name in names:
            obj = getattr(module, name)
            key = id(obj)
            if inspect.ismodule(obj):
                continue
            documented = inspect.isclass(obj) or inspect.isfunction(obj)
            if not documented:
                constants += _data(name, obj)
                continue
            if key in owner:
                elsewhere.append(f":py:obj:`{name} <{owner[key]}>`")
                continue
            owner[key] = f"{module_name}.{name}"
            own.append(name)
        if not own:
            continue
        title = _title(heading)
        lines += [title, "-" * len(title), "", ".. autosummary::", "   :toctree: generated",
                  "   :nosignatures:", "", *(f"   {n}" for n in own), ""]  # fmt: skip
    if constants:
        lines += ["Constants and types", "-------------------", "", *constants]
    if elsewhere:
        lines += ["Documented with another package", "-------------------------------", "",
                  "Also public here: " + ", ".join(elsewhere) + ".", ""]  # fmt: skip
    return "\n".join(lines)


def write(folder: Path) -> None:
    """Write ``index.rst`` and one page per face into ``folder`` (only files that changed)."""
    folder.mkdir(exist_ok=True)
    shutil.rmtree(folder / "generated", ignore_errors=True)  # autosummary writes it afresh
    owner: dict[int, str] = {}
    pages = {}
    for name, blurb in FACES:
        pages[f"{name}.rst"] = _page(name, blurb, owner)
    index = ["API reference", "=============", "",
             "Every public name, one page each, grouped as each package's docstring groups",
             "them. Start with :doc:`piezohyst`: what ``import piezohyst as ph`` gives.", "",
             ".. toctree::", "   :maxdepth: 1", "",
             *(f"   {name}" for name, _ in FACES), ""]  # fmt: skip
    pages["index.rst"] = "\n".join(index)
    for filename, text in pages.items():
        path = folder / filename
        if not path.exists() or path.read_text() != text:
            path.write_text(text)
