"""Helpers of the research tests: the product tests' own (repository root, real data, camera pools)."""

import json

from tests.conftest import REPO, SHARED_DATA, random_pool, shared_data

__all__ = ["REPO", "SHARED_DATA", "random_pool", "shared_data", "harness_unit"]


def harness_unit(ev, name: str, path, off=()) -> None:
    """A trained harness unit ``ev/name/metrics.json`` with per-view PSNRs: ``path`` for held-out
    frames on the capture path (``images/frame_<i>.jpg``), ``off`` for views off it
    (``images/offpath_<i>.jpg``)."""
    d = ev / name
    d.mkdir(parents=True)
    views = [{"name": f"images/frame_{i:04d}.jpg", "psnr": float(v)} for i, v in enumerate(path)]
    views += [{"name": f"images/offpath_{i:04d}.jpg", "psnr": float(v)} for i, v in enumerate(off)]
    (d / "metrics.json").write_text(json.dumps({"per_view": views}))
