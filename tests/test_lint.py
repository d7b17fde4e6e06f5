"""The code is linted on every test run (issue 51): ruff with the project's settings (pyproject.toml: syntax
errors, pyflakes, lines of at most 120 characters) over the package, the tests and research."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    pytest.importorskip("ruff", reason="ruff is one of the test tools (pip install -e '.[test]')")
    p = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "curate", "tests", "research", "scripts"],
                       cwd=ROOT, capture_output=True, text=True)
    assert p.returncode == 0, p.stdout[-4000:] + p.stderr[-2000:]
