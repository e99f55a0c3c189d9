"""No import circle inside a package of ``coils`` or ``coilrod`` (static, from the modules' ast).

Every ``import`` a module makes counts, at its top level or inside a function (a deferred import
hides a circle, it does not remove it); imports under ``if TYPE_CHECKING:`` do not run and do not
count. A module depends on a sibling when it imports it (``from .x import``, ``from . import x``
or ``from coils.x import``); the test fails on any cycle of those edges.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: Circles allowed for now, by package (none: every circle inside a package is gone; an entry
#: here would let one known circle stand while any new one fails).
KNOWN: dict[str, set[str]] = {}


def _packages():
    yield ROOT / "coils"
    yield from sorted(p.parent for p in (ROOT / "coilrod").rglob("__init__.py"))


def _runtime_imports(tree):
    """The import nodes that run: everything but the bodies of ``if TYPE_CHECKING:``."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            stack.extend(node.orelse)
            continue
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def sibling_imports(path: Path, package: str, siblings: set[str]) -> set[str]:
    """The sibling modules of ``package`` that the module at ``path`` imports."""
    out = set()
    for node in _runtime_imports(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names if a.name.startswith(package + ".")]
            out |= {n[len(package) + 1 :].split(".")[0] for n in names}
        elif node.level == 1 and node.module is None:
            out |= {a.name for a in node.names}
        elif node.level == 1:
            out.add(node.module.split(".")[0])
        elif node.level == 0 and node.module and node.module.startswith(package + "."):
            out.add(node.module[len(package) + 1 :].split(".")[0])
    return (out & siblings) - {path.stem}


def circles(graph: dict[str, set[str]]) -> list[set[str]]:
    """The strongly connected components with more than one module (Tarjan)."""
    index, low, on, stack, found = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(comp)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def package_graph(folder: Path) -> tuple[str, dict[str, set[str]]]:
    package = ".".join(folder.relative_to(ROOT).parts)
    modules = {p.stem: p for p in folder.glob("*.py") if p.stem != "__init__"}
    modules |= {p.name: p / "__init__.py" for p in folder.iterdir() if (p / "__init__.py").exists()}
    return package, {m: sibling_imports(p, package, set(modules)) for m, p in modules.items()}


@pytest.mark.parametrize("folder", list(_packages()), ids=lambda p: p.name)
def test_no_import_circle_inside_a_package(folder):
    package, graph = package_graph(folder)
    found = [c for c in circles(graph) if c != KNOWN.get(package)]
    assert not found, f"import circles inside {package}: {found}"


def test_the_detector_finds_a_circle_and_ignores_type_checking(tmp_path):
    """The checker itself: a -> b -> a is found (also through a function-level import), an
    ``if TYPE_CHECKING:`` import is not an edge."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from .b import f\n")
    (pkg / "b.py").write_text("def f():\n    from .a import g\n")
    (pkg / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import g\n"
    )
    (pkg / "d.py").write_text("from . import c\n")
    mods = {"a", "b", "c", "d"}
    graph = {m: sibling_imports(pkg / f"{m}.py", "pkg", mods) for m in mods}
    assert graph == {"a": {"b"}, "b": {"a"}, "c": set(), "d": {"c"}}
    assert circles(graph) == [{"a", "b"}]
