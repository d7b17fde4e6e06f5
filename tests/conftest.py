"""Shared test helpers: synthetic camera pools and the location of ../shared/data."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("CURATE_SHARED_DATA", REPO.parent / "shared" / "data"))


def shared_data(name: str) -> Path:
    """Path of a real data set beside the repo; skips the test when it is absent (a user's clone)."""
    p = SHARED_DATA / name
    if not p.exists():
        pytest.skip(f"real data {p} not found: it lives beside the repo in ../shared/data (CI has it)")
    return p


def random_pool(n: int, seed: int = 0, spread: float = 0.9, size=(320, 240), fx: float = 277.0,
                scale: float = 1.0, offset=(0.0, 0.0, 0.0)) -> Cameras:
    """n cameras at random points of [-spread, spread]^3 looking in random, mostly horizontal directions."""
    rng = np.random.default_rng(seed)
    c = rng.uniform(-spread, spread, (n, 3))
    d = rng.normal(size=(n, 3))
    d[:, 2] *= 0.3
    cams = Cameras(look_at(c, c + d), fx, fx, size[0] / 2, size[1] / 2, size[0], size[1])
    return cams.transformed(scale, None, np.asarray(offset, float))
