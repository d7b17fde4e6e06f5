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
    from research.import_map import modules
    return modules(ROOT)


def _layer(module: str) -> int:
    parts = module.split(".")
    if module in LEAVES or parts[1] == "core" or parts[-1] == "config":
        return 0
    for i, names in enumerate(LAYERS):
        if parts[1] in ((names,) if isinstance(names, str) else names):
            return i
    raise AssertionError(f"{module} is in no layer: add its package to LAYERS")


def _imports(modules: dict[str, Path]) -> dict[str, set[str]]:
    """{module: the curate modules it imports}, at the top or inside a function; TYPE_CHECKING blocks left out
    (they run at no time)."""
    from research.import_map import imports
    return imports(modules)[0]


def test_a_module_imports_only_its_own_layer_or_lower_ones():
    modules = _modules()
    bad = [f"{m} (layer {_layer(m)}) imports {t} (layer {_layer(t)})"
           for m, targets in _imports(modules).items() for t in targets if _layer(t) > _layer(m)]
    assert not bad, "\n".join(bad)


def _top_names(node: ast.AST) -> list[str]:
    if isinstance(node, ast.Import):
        return [a.name.split(".")[0] for a in node.names]
    return [(node.module or "").split(".")[0]] if isinstance(node, ast.ImportFrom) else []


def test_no_import_circles_between_modules_and_no_research_in_the_package():
    from research.import_map import circles
    modules = _modules()
    research = [f"{m}: {ast.unparse(n)}" for m, p in modules.items() for n in ast.walk(ast.parse(p.read_text()))
                if "research" in _top_names(n)]
    assert not research, research
    assert not circles(modules, _imports(modules))


def test_the_checks_see_imports_inside_functions_and_circles(tmp_path):
    """The checks themselves, on a small tree: an import inside a function counts (262 of them hid the circles
    before), one under TYPE_CHECKING does not, and two modules importing each other make a circle."""
    from research.import_map import circles, imports, modules
    files = {"curate/__init__.py": "", "curate/core/__init__.py": "", "curate/cli.py": "import curate.core.b\n",
             "curate/core/a.py": "def f():\n    from curate.cli import main\n",
             "curate/core/b.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import curate.core.a\n"
                                 "def g():\n    from curate.core.c import h\n",
             "curate/core/c.py": "from curate.core.b import g\n"}
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    mods = modules(tmp_path)
    edges = imports(mods)[0]
    assert edges["curate.core.a"] == {"curate.cli"} and edges["curate.core.b"] == {"curate.core.c"}
    assert _layer("curate.cli") > _layer("curate.core.a")          # what the layer test refuses
    assert circles(mods, edges) == [["curate.core.b", "curate.core.c"]]


def test_no_stage_imports_another_stages_module():
    """Issue 60: a stage reads another stage's results through the run's reader (:mod:`curate.core.run`, the SfM
    package's ``io`` and ``warn``), never through that stage's module; only the pipeline, the batch and the command
    line, which sequence the stages, import them."""
    from curate.core.graph import STAGES
    stages = {s.runs.split(":")[0] for s in STAGES}
    sequencers = ("pipeline", "batch", "cli", "__main__")
    bad = [f"{m} imports {t}" for m, targets in _imports(_modules()).items() for t in targets
           if t in stages and m.split(".")[1] not in sequencers and m.split(".")[1] != t.split(".")[1]]
    assert not bad, "\n".join(bad)
