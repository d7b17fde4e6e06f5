"""CI runs the README's test command, and that command hands the longest test files out first."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _root_conftest():
    """The repository's own conftest.py (``import conftest`` finds tests/conftest.py)."""
    spec = importlib.util.spec_from_file_location("root_conftest", ROOT / "conftest.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_ci_runs_the_readmes_test_command():
    readme = ROOT.joinpath("README.md").read_text()
    block = readme.split("The tests (what CI runs")[1]
    command = re.search(r"```bash\n(.+?)\n```", block, re.S).group(1).strip()
    assert "pytest" in command and "-n auto" in command
    assert command in ROOT.joinpath(".ci", "run").read_text().splitlines()


class _Item:
    def __init__(self, nodeid: str, slow: bool = False):
        self.nodeid, self.slow = nodeid, slow

    def get_closest_marker(self, name):
        return object() if name == "slow" and self.slow else None


def test_files_with_the_most_slow_tests_are_handed_out_first_and_keep_their_order():
    items = [_Item("tests/test_a.py::x"), _Item("tests/test_a.py::y", True),
             _Item("tests/test_b.py::x", True), _Item("tests/test_b.py::y"), _Item("tests/test_b.py::z", True),
             _Item("tests/test_c.py::x"),
             _Item("research/tests/test_d.py::x", True)]
    slow_first = _root_conftest().slow_first
    got = [it.nodeid for it in slow_first(items)]
    assert got == ["tests/test_b.py::x", "tests/test_b.py::y", "tests/test_b.py::z",        # 2 slow
                   "tests/test_a.py::x", "tests/test_a.py::y", "research/tests/test_d.py::x",  # 1 slow each, in order
                   "tests/test_c.py::x"]
    assert slow_first([]) == []
