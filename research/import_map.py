"""The map of curate's tree: modules, lines, imports between curate's modules (at module level and inside
functions; TYPE_CHECKING blocks left out), import circles (strongly connected components of modules) and the
packages that import each other.

``python -m research.import_map [ROOT]`` (default: this checkout) prints one JSON line; docs/architecture.md#layers
holds the table before and after issue 51's second pass.
"""

from __future__ import annotations

import ast
import collections
import json
import sys
from pathlib import Path


def modules(root: Path) -> dict[str, Path]:
    """{dotted name: file} of every module under ``root/curate``."""
    out = {}
    for p in (root / "curate").rglob("*.py"):
        name = ".".join(p.relative_to(root).with_suffix("").parts)
        out[name.removesuffix(".__init__")] = p
    return out


def imports(mods: dict[str, Path]) -> tuple[dict[str, set[str]], collections.Counter]:
    """({module: curate modules it imports}, counts of imports at module level and inside functions)."""
    edges: dict[str, set[str]] = collections.defaultdict(set)
    kinds: collections.Counter = collections.Counter()
    for m, p in mods.items():
        tree = ast.parse(p.read_text())
        parents = {c: node for node in ast.walk(tree) for c in ast.iter_child_nodes(node)}
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                cands = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                cands = [f"{node.module}.{a.name}" for a in node.names] + [node.module]
            else:
                continue
            target = next((c for c in cands if c in mods and c != m), None)
            if target is None:
                continue
            in_function = type_checking = False
            q = node
            while q in parents:
                q = parents[q]
                in_function |= isinstance(q, (ast.FunctionDef, ast.AsyncFunctionDef))
                type_checking |= isinstance(q, ast.If) and "TYPE_CHECKING" in ast.unparse(q.test)
            if not type_checking:
                kinds["function" if in_function else "module"] += 1
                edges[m].add(target)
    return edges, kinds


def circles(nodes, edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
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
                out.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return out


def main() -> None:
    root = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[1]
    mods = modules(root)
    edges, kinds = imports(mods)

    def package(m: str) -> str:
        return m.split(".")[1] if "." in m else m
    between = collections.defaultdict(set)
    for a, targets in edges.items():
        for b in targets:
            if package(a) != package(b) and b != "curate":
                between[package(a)].add(package(b))
    lines = {m: len(p.read_text().splitlines()) for m, p in mods.items()}
    print(json.dumps({"files": len(mods), "lines": sum(lines.values()),
                      "largest": sorted(lines.items(), key=lambda x: -x[1])[:3], "imports": dict(kinds),
                      "module_circles": circles(mods, edges),
                      "package_pairs_both_ways": sorted({tuple(sorted((a, b))) for a in between for b in between[a]
                                                         if a in between.get(b, ())})}))


if __name__ == "__main__":
    main()
