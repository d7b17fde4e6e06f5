"""One place to add a selection method: curate.select.methods.REGISTRY gives --method its choices and
help, the report its names, and select() its function."""

from __future__ import annotations

import subprocess
import sys

import pytest

from curate.core.grid import NodeGrid
from curate.select import methods
from curate.select.methods import REGISTRY, Method, get_method, method_help, method_label
from curate.select.config import SelectConfig
from curate.select.select import Selection, select
from conftest import random_pool


def run_first(cams, grid, budget, cfg, initial, index, progress=False):
    """A method made up for the test: the first cameras not yet chosen."""
    chosen = [k for k in range(len(cams)) if k not in initial][:budget]
    return Selection("first", chosen, list(initial), note="made up")


def test_a_method_added_to_the_registry_runs_is_offered_and_named(monkeypatch):
    monkeypatch.setitem(REGISTRY, "first", Method("first", "the first photos", "the first photos in name order",
                                                  "test_select_methods:run_first"))
    cams = random_pool(12, seed=1)
    sel = select(cams, NodeGrid([-1] * 3, [1] * 3, 6), 4, SelectConfig(method="first"), initial=[0])
    assert sel.method == "first" and sel.chosen == [1, 2, 3, 4] and sel.note == "made up"
    assert method_label("first") == "the first photos"
    assert "first    the first photos in name order" in method_help()


@pytest.mark.parametrize("key", [k for k in REGISTRY if k != "auto"])
def test_every_method_runs_through_its_entry(key):
    """select() dispatches through the registry: each entry's function gives that method's Selection."""
    cams = random_pool(20, seed=3)
    grid = NodeGrid([-1] * 3, [1] * 3, 6)
    sel = select(cams, grid, 5, SelectConfig(method=key))
    assert callable(get_method(key).run) and len(sel.chosen) == 5 and len(sel.energy) == 5
    assert sel.method == key or "fell back" in sel.note       # path on a random pool: view medoids, said so


def test_labels_and_help_are_for_people():
    assert method_label("path") == "even spacing along the capture path"
    assert method_label("a-research-variant") == "a-research-variant"
    labels = [m.label for m in REGISTRY.values()]
    assert len(set(labels)) == len(labels) and all(labels)
    lines = method_help().splitlines()[1:]
    assert [line.split()[0] for line in lines] == list(REGISTRY) and sum("(default)" in x for x in lines) == 1
    with pytest.raises(ValueError, match="unknown selection method 'best'"):
        get_method("best")
    with pytest.raises(ValueError, match="--method must be one of auto, path"):
        SelectConfig(method="best")
    with pytest.raises(ValueError, match="resolved to another method"):
        get_method("auto").run


def test_the_registry_imports_nothing_heavy():
    code = ("import sys, curate.select.methods as m; m.method_help(); m.method_label('path'); "
            "print(sorted(x for x in ('numpy', 'torch', 'curate.select.select') if x in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    assert methods.METHODS == tuple(REGISTRY)
