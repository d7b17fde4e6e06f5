"""The global bundle-adjustment schedule against a capture's observations (issue 58, item 4).

The incremental mapper adjusts the whole model each time it grows by a factor: COLMAP's 1.1, refined up to five
times, or curate's cheaper 1.5, refined once (:func:`curate.sfm.reconstruction.incremental_options`). A global
adjustment costs about its observations (the Jacobian's rows), not its photos: a 75-photo drone flight carries more
than a 371-frame walk. For each finished run folder (its ``sfm/database.db`` and working images), this maps the same
matches under both schedules, one after the other in this process, and prints one JSON line per run: the
observations the matches promise (:func:`curate.sfm.reconstruction.expected_observations`) and those of the model,
CPU and wall seconds of each mapping, its registered photos and points, and the cheaper model's poses against
COLMAP's schedule's (rotation, centre error relative to the scene's extent, after a similarity) and, with
``--truth``, both against a ground truth (a folder :func:`research.datasets.load_ground_truth` reads: fox,
templering, office; or a rendered capture's folder with its ``truth.npy``).

    python -m research.ba_by_observations RUN [RUN ...] [--truth RUN=PATH ...] [--repeat N]

With ``--repeat N`` each schedule maps N times; each repeat after the first records how far its poses are from the
first's (``against_first``).

Options that choose the schedule are set on :class:`curate.sfm.config.SfmConfig` by name (``--colmap`` and
``--cheaper``, FIELD=VALUE each), so the script runs on the code before and after the rule changed.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def _cams(models):
    from curate.sfm.model import cameras_from_reconstruction
    best = max(models.values(), key=lambda r: r.num_reg_images())
    obs = int(sum(p.track.length() for p in best.points3D.values()))
    return cameras_from_reconstruction(best, warn=False)[0], best, obs


def map_once(run: Path, overrides: dict) -> dict:
    """COLMAP's incremental mapper as ``curate sfm`` maps (one thread, seeded) on a copy of ``run``'s matches."""
    import pycolmap

    from curate.sfm.config import SfmConfig
    from curate.sfm.native import colmap_log
    from curate.sfm.reconstruction import map_incremental
    sfm = run / "sfm"
    tmp = Path(tempfile.mkdtemp())
    try:
        db = tmp / "d.db"
        copy_database(sfm / "database.db", db)
        n = len(list((sfm / "images").iterdir()))
        cfg = SfmConfig(progress=False, **overrides)
        pycolmap.set_random_seed(cfg.seed)
        r0, t0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
        with colmap_log(tmp / "colmap.log"):
            models = map_incremental(cfg, db, sfm / "images", tmp / "m", n, False)
        r1 = resource.getrusage(resource.RUSAGE_SELF)
        cams, best, obs = _cams(models)
        return {"wall_s": round(time.perf_counter() - t0, 1),
                "cpu_s": round(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime, 1),
                "registered": int(best.num_reg_images()), "n_photos": n, "points": int(len(best.points3D)),
                "model_observations": obs, "cams": cams}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _truth(path: str):
    p = Path(path)
    if (p / "truth.npy").is_file():          # a capture research.bench.bench_mapping or research.feature_rich rendered
        from research.bench.bench_mapping import truth_cameras
        return truth_cameras(p, "object" if p.name.startswith("object") else p.name.split("_s")[0])
    from research.datasets import load_ground_truth
    return load_ground_truth(p)


def _errors(est, ref) -> dict:
    from research.align import pose_errors
    e = pose_errors(est, ref)
    keys = ("rotation_deg_median", "rotation_deg_max", "centre_rel_median", "centre_rel_max")
    return {**{k: round(e[k], 4) for k in keys}, "n_matched": e["n_matched"],
            "n_over_5deg": int((np.asarray(e["rotation_deg"]) > 5).sum())}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--truth", nargs="*", default=[], help="RUN=PATH: that run's ground truth")
    ap.add_argument("--colmap", nargs="+", default=["global_ba_above_observations=1000000000"],
                    help="SfmConfig FIELD=VALUE giving COLMAP's schedule")
    ap.add_argument("--cheaper", nargs="+", default=["global_ba_above_observations=0"],
                    help="SfmConfig FIELD=VALUE giving curate's cheaper schedule")
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args(argv)
    from curate.sfm.reconstruction import expected_observations
    from research.sfm_mappers import sfm_config_overrides
    truths = dict(t.split("=", 1) for t in a.truth)
    for run in a.runs:
        row: dict = {"run": str(run), "expected_observations": expected_observations(run / "sfm" / "database.db")}
        cams, first = {}, {}
        for k in range(a.repeat):
            for label, ov in (("colmap", sfm_config_overrides(a.colmap)), ("cheaper", sfm_config_overrides(a.cheaper))):
                rec = map_once(run, ov)
                cams[label] = rec.pop("cams")
                if k == 0:
                    first[label] = cams[label]
                else:                               # the same matches mapped again: how far it moved
                    rec["against_first"] = _errors(cams[label], first[label])
                row.setdefault(label, []).append(rec)
                print(f"{run.name} {label} #{k}: {rec}", file=sys.stderr, flush=True)
        row["cheaper_vs_colmap"] = _errors(cams["cheaper"], cams["colmap"])
        if str(run) in truths:
            t = _truth(truths[str(run)])
            row["truth"] = {label: _errors(c, t) for label, c in cams.items()}
        print(json.dumps(row), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
