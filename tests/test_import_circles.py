"""No import circle inside a package of ``coils`` or ``coilrod`` (static, from the modules' ast),
and no function of theirs over :data:`MAX_LINES` lines of code.

Every ``import`` a module makes counts, at its top level or inside a function (a deferred import
hides a circle, it does not remove it); imports under ``if TYPE_CHECKING:`` do not run and do not
count. A module depends on a sibling when it imports it (``from .x import``, ``from . import x``
or ``from coils.x import``); the test fails on any cycle of those edges.

A function's lines of code are the lines from its ``def`` to its end that are neither blank nor
a comment nor part of a docstring (its own, or a nested function's or class's); a nested
function's lines count in the function around it too.
"""

from __future__ import annotations

import ast
import functools
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


@functools.cache
def _facts(path: Path) -> tuple[list, list]:
    """What both checks read of the module at ``path``, from one parse (the tree itself is not
    kept: a thousand modules' trees held alive slow the garbage collector for the rest of the
    run): its imports that run, as (level, module, names) -- level None for ``import x`` --
    and :func:`function_lengths`."""
    source = path.read_text(encoding="utf-8")
    tree = ast.parse(source)
    imports = [
        (
            None if isinstance(node, ast.Import) else node.level,
            None if isinstance(node, ast.Import) else node.module,
            [a.name for a in node.names],
        )
        for node in _runtime_imports(tree)
    ]
    return imports, function_lengths(source, tree)


def sibling_imports(path: Path, package: str, siblings: set[str]) -> set[str]:
    """The sibling modules of ``package`` that the module at ``path`` imports."""
    out = set()
    for level, module, names in _facts(path)[0]:
        if level is None:  # import x.y
            names = [n for n in names if n.startswith(package + ".")]
            out |= {n[len(package) + 1 :].split(".")[0] for n in names}
        elif level == 1 and module is None:
            out |= set(names)
        elif level == 1:
            out.add(module.split(".")[0])
        elif level == 0 and module and module.startswith(package + "."):
            out.add(module[len(package) + 1 :].split(".")[0])
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


#: The most lines of code a function of the library may have (issue 19, "Shape").
MAX_LINES = 100


def _definitions(tree):
    """Every function and class defined in ``tree``, at any depth (statements only: no
    expression holds a ``def``)."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            yield node
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            stack.extend(getattr(node, field, ()))


def function_lengths(source: str, tree) -> list[tuple[int, str, int]]:
    """(line, name, lines of code) of every function of the module ``source`` (parsed:
    ``tree``): the lines of its def through its end that are neither blank, nor a comment,
    nor in a docstring (its own or one of what it defines)."""
    defined = list(_definitions(tree))
    skip = set()
    for node in defined:
        first = node.body[0]
        if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
            if isinstance(first.value.value, str):
                skip.update(range(first.lineno, first.end_lineno + 1))
    upto = [0]  # upto[i]: lines of code among lines 1 .. i
    for i, line in enumerate(source.splitlines(), 1):
        text = line.strip()
        upto.append(upto[-1] + (i not in skip and bool(text) and not text.startswith("#")))
    return sorted(
        (node.lineno, node.name, upto[node.end_lineno] - upto[node.lineno - 1])
        for node in defined
        if not isinstance(node, ast.ClassDef)
    )


def long_functions(root: Path, limit: int = MAX_LINES) -> list[str]:
    """Every function of ``root``'s ``coils`` and ``coilrod`` over ``limit`` lines of code, as
    'path:line name (lines)'."""
    found = []
    for path in sorted([*(root / "coils").rglob("*.py"), *(root / "coilrod").rglob("*.py")]):
        for line, name, n in _facts(path)[1]:
            if n > limit:
                found.append(f"{path.relative_to(root).as_posix()}:{line} {name} ({n})")
    return found


def test_no_function_over_100_lines_of_code():
    found = long_functions(ROOT)
    assert not found, f"functions over {MAX_LINES} lines of code: {found}"


def test_the_line_count_leaves_out_docstrings_comments_and_blank_lines(tmp_path):
    """The counter itself: a function of 5 lines of code (a nested one's and a string's two
    lines included) among docstrings, a comment and a blank line: over a limit of 4, not 5."""
    source = """def f(x):
    '''Doc

    string.'''
    # a comment

    def g():
        '''Its doc.'''
        return '''a
b'''
    return g
"""
    (tmp_path / "coils").mkdir()
    (tmp_path / "coilrod").mkdir()
    (tmp_path / "coils" / "m.py").write_text(source)
    assert function_lengths(source, ast.parse(source)) == [(1, "f", 5), (7, "g", 3)]
    assert long_functions(tmp_path, 4) == ["coils/m.py:1 f (5)"]
    assert long_functions(tmp_path, 5) == []
