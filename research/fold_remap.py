"""A folded incremental model mapped again by the global mapper (measured, not adopted:
docs/investigations/sfm.md#hall-and-back): on a finished run whose incremental model's path jumps and does not come
back (``curate.sfm.continuity.jumps_along``), the global mapper on a copy of the same matches, the jumps of its own
path, and both models' pose errors against the rendered truth, one JSON line. The variant tried was
"keep the global model when its path does not jump and it holds as many photos": on the walk down a hall
and back the global model was far the better one (38 frames over 5 deg against 1,556) and its path still
jumped, so that rule would not have used it.

    python3 -m research.fold_remap RUN FRAMES KIND     # RUN: a `curate sfm` run of a research.bench.bench_mapping
                                                       # capture, FRAMES its rendered folder, KIND its capture kind
"""
from __future__ import annotations

import json
import shutil
import sys
import tempfile
import time
from pathlib import Path
from curate.sfm.matching import copy_database


def main(argv: list[str]) -> dict:
    import pycolmap

    from curate.sfm.continuity import drop_off_path, jumps_along
    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.native import colmap_log
    from curate.sfm.parts import without_contained
    from curate.sfm.reconstruction import map_global, model_sizes
    from curate.sfm.config import SfmConfig
    from research.bench.bench_mapping import pose_record, truth_cameras
    from research.path_check import kept_records
    run, frames, kind = Path(argv[0]), Path(argv[1]), argv[2]
    sfm = run / "sfm"
    kept = kept_records(run)
    truth = truth_cameras(frames, kind)
    best = pycolmap.Reconstruction(sfm / "sparse" / "0")
    rec: dict = {"run": str(run), "incremental": {
        "photos": int(best.num_reg_images()), "jumps": jumps_along(best, kept),
        **pose_record(cameras_from_reconstruction(best, warn=False)[0], truth)}}
    tmp = Path(tempfile.mkdtemp())
    copy_database(sfm / "database.db", tmp / "g.db")
    t = time.perf_counter()
    with colmap_log(tmp / "colmap.log"):
        glob = without_contained(map_global(SfmConfig(progress=False), tmp / "g.db", sfm / "images", tmp / "g"))
    rec["seconds"] = round(time.perf_counter() - t, 1)
    if glob:
        off = drop_off_path(glob, kept)
        g = max(glob.values(), key=lambda r: r.num_reg_images())
        rec["global"] = {"model_sizes": model_sizes(glob), "photos": int(g.num_reg_images()), "off_path": off,
                         "jumps": jumps_along(g, kept),
                         **pose_record(cameras_from_reconstruction(g, warn=False)[0], truth)}
    shutil.rmtree(tmp)
    return rec


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])), flush=True)
