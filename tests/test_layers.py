"""The package's layers (issue 51): cli -> pipeline/batch -> stages in the graph's order -> field/html -> core and
the leaf configs. A module imports only its own layer or lower ones, whether at the top of the file or inside
a function; no two modules import each other, directly or through others; curate never imports research."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LEAVES = ("curate", "curate.config", "curate.select.methods", "curate.select.bins", "curate.suggest.choices",
          "curate.simulate.choices")
"""Modules of the lowest layer besides ``curate.core.*`` and every package's ``config``: light, importable by all."""

LAYERS = ("core", ("field", "html"), "sfm", "occupancy", "select", "evaluate", "export", "report", "simulate",
          "suggest", "pipeline", "batch", ("cli", "__main__"))
"""From the lowest: ``curate.<name>`` (a package or a module) and its layer."""


def _modules() -> dict[str, Path]:
    out = {}
    for p in (ROOT / "curate").rglob("*.py"):
        name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        out[name[: -len(".__init__")] if name.endswith(".__init__") else name] = p
    return out


def _layer(module: str) -> int:
    parts = module.split(".")
    if module in LEAVES or parts[1] == "core" or parts[-1] == "config":
        return 0
    for i, names in enumerate(LAYERS):
        if parts[1] in ((names,) if isinstance(names, str) else names):
            return i
    raise AssertionError(f"{module} is in no layer: add its package to LAYERS")


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    """{module: the curate modules it imports}, TYPE_CHECKING blocks left out (they run at no time)."""
    out: dict[str, set[str]] = {}
    for name, path in modules.items():
        tree = ast.parse(path.read_text())
        skip = {id(n) for node in ast.walk(tree)
                if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        found = set()
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                cands = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                cands = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            else:
                continue
            for c in cands:
                if c.split(".")[0] == "research":
                    found.add(c)
                elif c in modules and c != name:
                    found.add(c)
                    break
        out[name] = found
    return out


def test_a_module_imports_only_its_own_layer_or_lower_ones():
    modules = _modules()
    bad = [f"{m} (layer {_layer(m)}) imports {t} (layer {_layer(t)})"
           for m, targets in _imports(modules).items() for t in targets
           if not t.startswith("research") and _layer(t) > _layer(m)]
    assert not bad, "\n".join(bad)


def test_no_import_circles_between_modules_and_no_research_in_the_package():
    modules = _modules()
    imports = _imports(modules)
    assert not [f"{m} imports {t}" for m, ts in imports.items() for t in ts if t.startswith("research")]
    graph = {m: {t for t in ts if t in modules and t != "curate"} for m, ts in imports.items()}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    circles: list[list[str]] = []

    def visit(v: str) -> None:            # Tarjan's strongly connected components
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
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                circles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    assert not circles, circles


def test_the_layer_check_sees_a_function_level_import_upward():
    """The check itself: an import inside a function counts (262 of them hid the circles before)."""
    src = "def f():\n    from curate.cli import main\n"
    tree = ast.parse(src)
    names = [n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
    assert names == ["curate.cli"] and _layer("curate.cli") > _layer("curate.core.stage")
    assert _layer("curate.select.config") == 0 < _layer("curate.field.model") < _layer("curate.sfm.colmap")
