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


@pytest.fixture()
def unprivileged():
    """A context manager ``with unprivileged(*paths):`` whose block runs as a user would: a file or folder with
    mode 000 cannot be read. As root (a container, this project's machines) the ``paths`` (trees) are handed to
    ``nobody``, their parent folders made passable, and the effective user and group switched for the block,
    then all put back; as a user it does nothing. Skips where the switch is refused."""
    import contextlib
    import stat as st

    @contextlib.contextmanager
    def cm(*paths):
        if not hasattr(os, "geteuid") or os.geteuid() != 0:
            yield
            return
        uid, gid = 65534, 65534
        owners, modes = {}, {}
        for top in map(Path, paths):
            for d, dirs, files in os.walk(top):
                for q in [Path(d)] + [Path(d) / n for n in dirs + files]:
                    s = q.lstat()
                    owners[q] = (s.st_uid, s.st_gid)
                    os.lchown(q, uid, gid)
            for a in top.resolve().parents:
                s = a.stat()
                if not s.st_mode & st.S_IXOTH:
                    modes.setdefault(a, s.st_mode)
                    os.chmod(a, s.st_mode | st.S_IXOTH)
        try:
            os.setegid(gid)
            os.seteuid(uid)
        except OSError as e:   # pragma: no cover
            pytest.skip(f"cannot run as nobody here: {e}")
        try:
            yield
        finally:
            os.seteuid(0)
            os.setegid(0)
            for q, (u, g) in owners.items():
                if os.path.lexists(q):
                    os.lchown(q, u, g)
            for a, m in modes.items():
                os.chmod(a, m)
    return cm
