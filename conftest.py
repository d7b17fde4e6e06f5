"""Test-session hooks for the whole repository (tests/ and research/tests/).

The README's test command runs the tests on every core (pytest-xdist's ``-n auto``) a test file at a time
(``--dist loadfile``, pyproject's addopts), so that a fixture a file's tests share (the fox mapped once, a
rendered room) is built once, as in one process. Files are handed out in the order collected: under xdist the
files with the most tests marked slow come first, so that the longest files do not start last and leave the
other cores idle at the end (docs/results.md#test-time).
"""

from __future__ import annotations

from collections import Counter


def slow_first(items: list) -> list:
    """``items`` with the files that hold the most tests marked slow first (stable: each file's tests, and files
    of equal count, keep their order)."""
    files = [it.nodeid.split("::")[0] for it in items]
    slow = Counter(f for f, it in zip(files, items) if it.get_closest_marker("slow"))
    first = {f: i for i, f in enumerate(dict.fromkeys(files))}
    return [items[i] for i in sorted(range(len(items)), key=lambda i: (-slow[files[i]], first[files[i]]))]


def pytest_collection_modifyitems(config, items):
    if hasattr(config, "workerinput"):   # a pytest-xdist worker: every worker collects, and sorts, alike
        items[:] = slow_first(items)
