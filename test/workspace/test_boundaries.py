"""Boundaries inside each package, read from the source with ``ast`` (nothing imported).

- No folder-level import cycle: if any module of folder A imports folder B
  (at top level or inside a function), no module of B imports A. A cycle
  means neither folder can be read, tested or replaced without the other.
- No private name crosses a module boundary: ``from m import _x`` and
  ``m._x`` on an imported project module are refused (a name another module
  needs is public, documented, and in ``__all__``).
- No function longer than :data:`MAX_FUNCTION_LINES` (a longer one is split into
  named steps).
- Each requirement is listed once (requirements*.txt, setup.py, package.xml).

The import graph is built independently of the layering test (test_layout.py,
which checks the direction between packages): relative imports are resolved
against the importing module's package, and ``from pkg import sub`` is
counted as an import of ``pkg.sub`` when ``sub`` is a module or folder.
"""

from __future__ import annotations

import ast
import re
import sys
import xml.etree.ElementTree as ET
from collections import defaultdict
from functools import cache
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SRC = ROOT / "src"
PACKAGES = sorted(p.name for p in SRC.iterdir() if (p / "package.xml").is_file())

# Folder cycles that exist in folders being rewritten elsewhere (issue 23); each entry names
# the pair in sorted order. Remove an entry when its cycle is gone: it cannot come back then.
KNOWN_CYCLES: dict[str, set[tuple[str, str]]] = {
    "pneu_control": {("algorithms", "controller")},
}
# Private names still imported across modules, in folders being rewritten elsewhere:
# (importing module, imported module, name).
KNOWN_PRIVATE: set[tuple[str, str, str]] = set()

MAX_FUNCTION_LINES = 80


@cache
def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def _modules(pkg: str) -> dict[str, Path]:
    """Dotted module name -> file, for every module of ``src/<pkg>/<pkg>``."""
    out = {}
    for path in sorted((SRC / pkg / pkg).rglob("*.py")):
        parts = list(path.relative_to(SRC / pkg).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, known: set[str]) -> list[tuple[str, int, list[str]]]:
    """(imported module, line, names taken from it) of every import in the module ``name``."""
    tree = _tree(path)
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, node.lineno, []) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            names = [a.name for a in node.names]
            out.append((module, node.lineno, names))
            # `from pkg import sub`: sub is a module (or folder) of its own
            out += [(f"{module}.{n}", node.lineno, []) for n in names if f"{module}.{n}" in known]
    return out


def _folder(module: str) -> str | None:
    """The top folder of a project module ("pneu_control.experiment.runner" -> "experiment")."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def folder_edges(pkg: str) -> dict[tuple[str, str], list[str]]:
    """(folder A, folder B) -> "module:line imports module" for each import of B from A."""
    mods = _modules(pkg)
    folders = {p.name for p in (SRC / pkg / pkg).iterdir() if (p / "__init__.py").is_file()}
    edges: dict[tuple[str, str], list[str]] = defaultdict(list)
    for name, path in mods.items():
        src = _folder(name)
        for module, line, _ in _imports(name, path, set(mods)):
            if not module.startswith(pkg + "."):
                continue
            dst = _folder(module)
            if src in folders and dst in folders and src != dst:
                edges[(src, dst)].append(f"{name}:{line} imports {module}")
    return edges


def folder_cycles(pkg: str) -> dict[tuple[str, str], list[str]]:
    """Pairs of folders (sorted) that import each other, with the imports both ways.

    A longer cycle (A -> B -> C -> A) is found too: each pair of folders on it
    reaches the other through the graph; it is reported as the pair with one
    import from each side.
    """
    edges = folder_edges(pkg)
    graph: dict[str, set[str]] = defaultdict(set)
    for a, b in edges:
        graph[a].add(b)

    def reach(a: str) -> set[str]:
        seen, todo = set(), [a]
        while todo:
            for b in graph[todo.pop()]:
                if b not in seen:
                    seen.add(b)
                    todo.append(b)
        return seen

    reachable = {a: reach(a) for a in list(graph)}
    out = {}
    for a in sorted(reachable):
        for b in sorted(reachable[a]):
            if a < b and a in reachable.get(b, set()):
                out[(a, b)] = (
                    edges.get((a, b), [f"{a} reaches {b} indirectly"])[:3]
                    + edges.get((b, a), [f"{b} reaches {a} indirectly"])[:3]
                )
    return out


def test_the_cycle_finder_finds_cycles(tmp_path, monkeypatch):
    """The checker on a made-up package: a direct cycle, an indirect one, a relative import."""
    pkg = tmp_path / "demo" / "demo"
    for folder, text in {
        "a": "from demo.b.x import f\n",
        "b": "def g():\n    from ..a import m\n",
        "c": "import demo.d.y\n",
        "d": "from demo.e import z\n",
        "e": "from demo import c\n",
        "f": "from demo.a import m\n",  # f -> a only: no cycle
    }.items():
        (pkg / folder).mkdir(parents=True)
        (pkg / folder / "__init__.py").write_text("")
        (pkg / folder / "m.py").write_text(text)
    (pkg / "__init__.py").write_text("")
    monkeypatch.setattr(sys.modules[__name__], "SRC", tmp_path)
    found = folder_cycles("demo")
    assert set(found) == {("a", "b"), ("c", "d"), ("c", "e"), ("d", "e")}
    assert any("demo.b.m:2 imports demo.a.m" in line for line in found[("a", "b")])


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_folder_level_import_cycles(pkg):
    cycles = folder_cycles(pkg)
    new = {pair: lines for pair, lines in cycles.items() if pair not in KNOWN_CYCLES.get(pkg, ())}
    assert not new, "\n".join(
        f"{pkg}: {a} <-> {b}:\n    " + "\n    ".join(lines) for (a, b), lines in new.items()
    )


def private_uses(pkg: str) -> list[str]:
    """``from m import _x`` and ``m._x`` in ``pkg``'s modules, ``m`` another project module."""
    mods = _modules(pkg)
    every = {m for p in PACKAGES for m in _modules(p)}
    project = tuple(f"{p}." for p in PACKAGES)
    out = []
    for name, path in mods.items():
        bound = {}  # local name -> the project module it is bound to
        for module, line, names in _imports(name, path, every):
            if not module.startswith(project) or module == name:
                continue
            for n in names:
                if f"{module}.{n}" in every:
                    bound[n] = f"{module}.{n}"
                elif n.startswith("_") and (name, module, n) not in KNOWN_PRIVATE:
                    out.append(f"{name}:{line} from {module} import {n}")
        for node in ast.walk(_tree(path)):
            if isinstance(node, ast.Import):
                bound.update({a.asname: a.name for a in node.names if a.asname})
            elif (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and bound.get(node.value.id, name) != name
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
            ):
                out.append(f"{name}:{node.lineno} {bound[node.value.id]}.{node.attr}")
    return out


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_private_name_crosses_a_module(pkg):
    bad = private_uses(pkg)
    assert not bad, "private names used across modules:\n  " + "\n  ".join(bad)


def long_functions(pkg: str) -> list[tuple[str, str, int]]:
    """(module, [Class.]function, lines) of every function of ``pkg`` over the limit."""
    out = []
    for name, path in _modules(pkg).items():
        tree = _tree(path)

        def visit(body, prefix, name=name):
            for node in body:
                if isinstance(node, ast.ClassDef):
                    visit(node.body, f"{prefix}{node.name}.")
                elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        out.append((name, prefix + node.name, n))
                    visit(node.body, f"{prefix}{node.name}.")

        visit(tree.body, "")
    return out


@pytest.mark.parametrize("pkg", PACKAGES)
def test_no_function_over_the_line_limit(pkg):
    bad = long_functions(pkg)
    assert not bad, "\n".join(f"{m}.{f}: {n} lines (limit {MAX_FUNCTION_LINES})" for m, f, n in bad)


def _requirement_names(lines: list[str]) -> list[str]:
    out = []
    for line in lines:
        line = line.split("#", 1)[0].strip()
        if line and not line.startswith("-"):
            out.append(re.split(r"[<>=!~\[;, ]", line, maxsplit=1)[0].lower().replace("_", "-"))
    return out


def _duplicates(names: list) -> list:
    return sorted({n for n in names if names.count(n) > 1})


@pytest.mark.parametrize("path", sorted(ROOT.glob("requirements*.txt")), ids=lambda p: p.name)
def test_each_requirement_listed_once(path):
    assert not _duplicates(_requirement_names(path.read_text().splitlines())), path.name


@pytest.mark.parametrize("pkg", PACKAGES)
def test_each_package_dependency_listed_once(pkg):
    tree = ast.parse((SRC / pkg / "setup.py").read_text())
    requires = []
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == "install_requires":
            requires = [ast.literal_eval(e) for e in node.value.elts]
    assert not _duplicates(_requirement_names(requires)), f"{pkg}/setup.py install_requires"
    root = ET.parse(SRC / pkg / "package.xml").getroot()
    deps = [(e.tag, e.text) for e in root if e.tag.endswith("depend")]
    assert not _duplicates(deps), f"{pkg}/package.xml"
