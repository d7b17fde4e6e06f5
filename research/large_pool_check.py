"""Checks a global model of a large pool could carry instead of the incremental parts (issue 36, part 5).

``--mapper auto`` trusts COLMAP's global mapper only where the incremental mapper's parts confirm it,
and the incremental mapper's time grows faster than the square of the pool. For pools past 1,000
photos, two cheaper checks of a global model are measured here on a run folder whose SfM kept a
global model (``curate sfm PHOTOS --mapper global``) of a rendered capture with ground truth:

1. every frame checked by its own evidence (:func:`curate.sfm.parts.verify_frames`: PnP from its
   matches to the points the other frames see, the model held fixed): which frames it refuses,
   against the frames the truth says are wrong (over 5 deg, or a centre off by 5% of the extent);
2. an incremental model of every k-th photo only (the pool cut to at most ``--subsample`` photos):
   its time, and how far the global model disagrees with it
   (:func:`curate.sfm.parts.part_agreement`, the check ``auto`` applies to incremental parts).

    python3 -m research.large_pool_check /tmp/curate_bench_mapping/runs/walk_3000 \\
        --frames /tmp/curate_bench_mapping/frames/walk_livingroom_s0_n3000 --subsample 400

Prints one JSON object.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path, help="a run folder whose SfM kept a global model (RUN/sfm/sparse/0)")
    ap.add_argument("--frames", type=Path, required=True, help="the rendered capture's folder (truth.npy)")
    ap.add_argument("--kind", default="walk", help="the rendered capture's kind (walk, object)")
    ap.add_argument("--subsample", type=int, default=400, help="the most photos of the incremental check")
    a = ap.parse_args(argv)
    import pycolmap

    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.native import colmap_log
    from curate.sfm.parts import part_agreement, verify_frames
    from curate.sfm.config import SfmConfig
    from research.align import pose_errors
    from research.bench.bench_mapping import truth_cameras
    from research.sfm_mappers import map_subset
    sfm = a.run / "sfm"
    rec = pycolmap.Reconstruction(str(sfm / "sparse" / "0"))
    names = sorted(im.name for im in rec.images.values() if im.has_pose)
    e = pose_errors(cameras_from_reconstruction(rec, warn=False)[0], truth_cameras(a.frames, a.kind))
    err, cen = dict(zip(e["names"], e["rotation_deg"])), dict(zip(e["names"], e["centre_rel"]))
    bad = {n for n in err if err[n] > 5 or cen[n] > 0.05}
    out: dict = {"run": str(a.run), "frames": len(names), "wrong_by_truth": sorted(bad)}

    t = time.perf_counter()
    v = verify_frames(rec, names, SfmConfig().max_part_disagreement_deg)
    refused = {n for n, x in v.items() if not x["ok"]}
    out["verify_every_frame"] = {"seconds": round(time.perf_counter() - t, 1), "refused": len(refused),
                                 "wrong_refused": len(bad & refused), "wrong_kept": sorted(bad - refused),
                                 "right_refused": len(refused - bad),
                                 "why": {n: v[n]["why"] for n in sorted(refused)[:10]}}
    print(json.dumps({"verify_every_frame": out["verify_every_frame"]}), flush=True)

    k = int(2 ** np.ceil(np.log2(max(1.0, len(names) / a.subsample))))   # a power of two: sequential
    sub = names[::k]                                                      # matching pairs frames 2^j apart
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "d.db"
        copy_database(sfm / "database.db", db)
        c0, t = time.process_time(), time.perf_counter()
        with colmap_log(Path(tmp) / "colmap.log"):
            parts = map_subset(db, sfm / "images", Path(tmp) / "m", sub)
        secs, cpu = time.perf_counter() - t, time.process_time() - c0
    sizes = sorted((int(r.num_reg_images()) for r in parts.values()), reverse=True)
    checks = part_agreement({0: rec}, parts)
    out["incremental_subsample"] = {"every": k, "photos": len(sub), "seconds": round(secs, 1),
                                    "cpu_s": round(cpu, 1), "model_sizes": sizes,
                                    "disagreement_p90_deg": [d for d, _ in checks]}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
