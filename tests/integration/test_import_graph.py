"""The package's import graph, read statically (ast over kindyngen/**/*.py, nothing imported):
no import circle among its modules (imports inside functions count: a deferred import hides a
circle from Python, not from a reader), and no module imports the benchmarks or the tests
(a user's installed package has neither). Imports under ``if TYPE_CHECKING:`` never run and are
left out."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = ROOT / "kindyngen"
# the repository's own folders and the test helpers put on sys.path by tests/conftest.py
FORBIDDEN = {"benchmarks", "tests", "conftest", "harness", "reference"}


def _module_name(path: Path, root: Path = ROOT) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules(package: Path = PACKAGE) -> dict[str, Path]:
    root = package.parent
    return {_module_name(p, root): p for p in sorted(package.rglob("*.py"))}


def _type_checking_only(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _import_nodes(tree: ast.AST):
    """Every Import / ImportFrom in the module, at any depth, except under TYPE_CHECKING."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.If) and _type_checking_only(node):
            stack.extend(node.orelse)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        stack.extend(ast.iter_child_nodes(node))


def imports(name: str, path: Path, known: set[str]) -> tuple[set[str], set[str]]:
    """(the package modules ``name`` imports, every absolute top-level name it imports).

    ``from .a import b`` is an edge to ``pkg.a.b`` when that is a module, else to ``pkg.a``
    (``b`` is a name defined there); ``from . import x`` likewise."""
    is_package = path.name == "__init__.py"
    edges, top = set(), set()
    for node in _import_nodes(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                top.add(alias.name.split(".")[0])
                if alias.name in known:
                    edges.add(alias.name)
            continue
        if node.level:
            base = name.split(".")
            base = base[:len(base) - node.level + (1 if is_package else 0)]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module
            top.add(target.split(".")[0])
        for alias in node.names:
            sub = f"{target}.{alias.name}"
            if sub in known:
                edges.add(sub)
            elif target in known:
                edges.add(target)
    edges.discard(name)
    return edges, top


def graph(package: Path = PACKAGE) -> tuple[dict[str, set[str]], dict[str, set[str]]]:
    modules = _modules(package)
    known = set(modules)
    edges, tops = {}, {}
    for name, path in modules.items():
        edges[name], tops[name] = imports(name, path, known)
    return edges, tops


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each as a
    closed path through it, so a failure names the modules of every circle."""
    index, low, on_stack, stack, components = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                components.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return [_path_through(c, edges) for c in components]


def _path_through(component: list[str], edges: dict[str, set[str]]) -> list[str]:
    """A circle from the component's first module back to it (breadth first inside it)."""
    start, members = component[0], set(component)
    previous = {start: None}
    frontier = [start]
    while frontier:
        following = []
        for v in frontier:
            for w in sorted(edges[v] & members):
                if w == start:
                    path = [v]
                    while previous[path[-1]] is not None:
                        path.append(previous[path[-1]])
                    return path[::-1] + [start]
                if w not in previous:
                    previous[w] = v
                    following.append(w)
        frontier = following
    return component


def test_no_import_circles():
    edges, _ = graph()
    assert len(edges) > 40          # the walk found the package (flat modules and measured/)
    found = cycles(edges)
    assert not found, "import circles in kindyngen: " + "; ".join(" -> ".join(c) for c in found)


def test_no_module_imports_benchmarks_or_tests():
    _, tops = graph()
    offending = {name: sorted(t & FORBIDDEN) for name, t in tops.items() if t & FORBIDDEN}
    assert not offending, f"package modules importing benchmark or test code: {offending}"


# -- the checker itself, on a small package written here ------------------------------------
def _write(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return root / "pkg"


def test_checker_finds_a_circle_through_a_deferred_import(tmp_path):
    package = _write(tmp_path, {
        "pkg/__init__.py": "",
        "pkg/a.py": "from .b import f\n",
        "pkg/b.py": "def f():\n    from .sub import c\n",
        "pkg/sub/__init__.py": "",
        "pkg/sub/c.py": "from .. import a\nimport benchmarks.run\n",
        "pkg/d.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import x\nfrom . import a\n",
    })
    edges, tops = graph(package)
    assert edges["pkg.sub.c"] == {"pkg.a"} and edges["pkg.b"] == {"pkg.sub.c"}
    assert edges["pkg.d"] == {"pkg.a"}           # the TYPE_CHECKING import is not an edge
    assert cycles(edges) == [["pkg.a", "pkg.b", "pkg.sub.c", "pkg.a"]]
    assert "benchmarks" in tops["pkg.sub.c"]


def test_checker_passes_a_tree(tmp_path):
    package = _write(tmp_path, {"pkg/__init__.py": "", "pkg/a.py": "from .b import f\nimport numpy\n",
                                "pkg/b.py": "import os\n"})
    edges, tops = graph(package)
    assert cycles(edges) == [] and edges["pkg.a"] == {"pkg.b"} and tops["pkg.a"] == {"numpy"}


@pytest.mark.parametrize("edges, expected", [
    ({"x": {"y"}, "y": {"x"}}, [["x", "y", "x"]]),
    ({"x": {"y"}, "y": {"z"}, "z": {"x"}, "w": {"x"}}, [["x", "y", "z", "x"]]),
    ({"x": {"y"}, "y": set()}, []),
])
def test_cycles_on_hand_made_graphs(edges, expected):
    assert cycles(edges) == expected
