"""Helpers of the research tests: the repository root and the real data beside it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SHARED_DATA = Path(os.environ.get("CURATE_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_data(name: str) -> Path:
    """Path of a real data set beside the repo; skips the test when it is absent (a user's clone)."""
    p = SHARED_DATA / name
    if not p.exists():
        pytest.skip(f"real data {p} not found: it lives beside the repo in ../shared/data (CI has it)")
    return p
