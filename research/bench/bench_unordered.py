#!/usr/bin/env python
"""Benchmark the matching of photo folders in no order: retrieval against exhaustive, 300 to 2,000 photos.

    python3 -m research.bench.bench_unordered --sizes 300 1000 2000 --matchers retrieval exhaustive \\
        --exhaustive-upto 300 --map-upto 1000 [--work /tmp/curate_bench_unordered]

The pool of size N is the first N frames of a rendered 2,000-frame hand-held loop walk through the synthetic
living room (:func:`research.bench.bench_mapping.render`, 640x480, motion blur), given as photos whose names
are a hash of the frame's (no order, no GPS: ``--matcher auto`` picks retrieval past 150 photos). For each
pool and matcher: ingest, SIFT extraction and matching, each timed (wall and CPU seconds of this process,
all its threads), the image pairs matched and verified; for pools of at most ``--map-upto`` photos the model
too (mapping time, photos registered, pose error against the rendered truth after a similarity alignment).
Exhaustive matching past ``--exhaustive-upto`` photos is not run (its pairs grow as N^2 / 2). One JSON line
per cell, as it finishes.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
from pathlib import Path

from research.bench.bench_mapping import _clock, _since


def hashed_pool(work: Path, frames: Path, n: int) -> tuple[Path, dict[str, str]]:
    """A folder of hard links to the first ``n`` frames, each named by a hash of its frame's name; and
    {hashed name: frame name}."""
    names = sorted(p.name for p in frames.glob("frame_*.jpg"))[:n]
    if len(names) < n:
        raise RuntimeError(f"{frames}: {len(names)} frames rendered, {n} needed")
    dst = work / "pools" / f"hashed_{n}"
    dst.mkdir(parents=True, exist_ok=True)
    back = {}
    for nm in names:
        h = hashlib.sha1(nm.encode()).hexdigest()[:12] + ".jpg"
        back[h] = nm
        if not (dst / h).exists():
            os.link(frames / nm, dst / h)
    return dst, back


def cell(work: Path, frames: Path, n: int, matcher: str, map_it: bool, k: int) -> dict:
    from curate.core.cameras import Cameras
    from curate.sfm.config import SfmConfig
    from curate.sfm.features import extract
    from curate.sfm.matching import match, pair_counts
    from curate.sfm.prep import choose_camera_mode, prepare_photos, takes_of
    from research.align import pose_errors
    from research.bench.bench_mapping import truth_cameras

    pool, back = hashed_pool(work, frames, n)
    cfg = SfmConfig(matcher=matcher, progress=False, **({"retrieval_num_images": k} if matcher == "retrieval" else {}))
    out = work / "runs" / f"{matcher}{k if matcher == 'retrieval' else ''}_{n}"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    rec: dict = {"n": n, "matcher": matcher, **({"retrieval_num_images": k} if matcher == "retrieval" else {})}
    t = _clock()
    _, kept, _ = prepare_photos(cfg, pool, out)
    rec["ingest"] = _since(t)
    names = [r.working for r in kept]
    db, images = out / "database.db", out / "images"
    t = _clock()
    extract(cfg, db, images, names, choose_camera_mode(cfg, kept))
    rec["extract"] = _since(t)
    t = _clock()
    match(cfg, db, matcher, takes_of(kept), {})
    rec["match"] = _since(t)
    rec["pairs_matched"], rec["pairs_verified"] = pair_counts(db, cfg.min_num_matches)
    rec["n_kept"] = len(names)
    if map_it:
        from curate.sfm.parts import without_contained
        from curate.sfm.model import cameras_from_reconstruction
        from curate.sfm.reconstruction import map_capture
        t = _clock()
        models = without_contained(map_capture(cfg, db, images, out / "mapper", len(names), {}))
        rec["map"] = _since(t)
        best = max(models.values(), key=lambda r: r.num_reg_images()) if models else None
        rec["registered"] = int(best.num_reg_images()) if best else 0
        rec["model_sizes"] = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
        if best is not None:
            cams = cameras_from_reconstruction(best, warn=False)[0]
            src = {r.working: r.rel for r in kept}
            est = Cameras(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height,
                          names=tuple(back[Path(src[nm]).name] for nm in cams.names))
            e = pose_errors(est, truth_cameras(frames, "walk"))
            rec["pose"] = {k2: round(float(v), 3) for k2, v in e.items() if isinstance(v, (int, float))}
    shutil.rmtree(out / "images", ignore_errors=True)          # the working copies: disk
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[300, 1000, 2000])
    ap.add_argument("--matchers", nargs="+", default=["retrieval", "exhaustive"])
    ap.add_argument("--retrieval-k", type=int, nargs="+", default=[30], help="retrieval_num_images values")
    ap.add_argument("--exhaustive-upto", type=int, default=300)
    ap.add_argument("--map-upto", type=int, default=1000)
    ap.add_argument("--work", type=Path, default=Path("/tmp/curate_bench_unordered"))
    a = ap.parse_args(argv)
    from research.bench.bench_mapping import render
    frames = render(a.work, "walk", 2000, max(a.sizes))
    for n in a.sizes:
        for m in a.matchers:
            if m == "exhaustive" and n > a.exhaustive_upto:
                continue
            for k in (a.retrieval_k if m == "retrieval" else [0]):
                print(json.dumps(cell(a.work, frames, n, m, n <= a.map_upto, k)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
