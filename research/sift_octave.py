"""SIFT from the doubled working copy (COLMAP's first octave -1) or from the copy itself: what each costs and
what the model loses (issue 58, item 4). docs/investigations/sfm.md#sift-octave.

``curate sfm`` of one capture once per setting of ``--sift-upsample-below`` (each in a fresh run folder, one after
the other, in its own process: research.bench.bench_mapping's ``sfm_child``), then prints one JSON object: each
run's stage times (wall and CPU seconds), the photos' median SIFT features, registered photos and model sizes,
and its poses against the reference: the capture's truth where it has one (a shared set with ground truth, or a
rendered capture's frame folder), else the first setting's model.

    python -m research.sift_octave PHOTOS --work W [--settings 100000 1000] [--truth FOLDER [--kind object]]
        [--sfm-args ...] [--reuse]
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np


def features_median(run: Path) -> float:
    """The median number of SIFT keypoints of the photos in ``run``'s database."""
    from curate.sfm.native import load
    pycolmap = load()
    from research.rundb import database_copy
    with database_copy(run / "sfm" / "database.db") as copy, pycolmap.Database.open(copy) as db:
        return float(np.median([db.num_keypoints_for_image(im.image_id) for im in db.read_all_images()]))


def one(work: Path, photos: Path, below: int, extra: list[str], reuse: bool = False) -> dict:
    from research.bench.bench_mapping import _timed
    name = f"below{below}"
    run, steps, saved = work / "runs" / name, work / f"{name}.steps.json", work / f"{name}.json"
    if reuse and saved.is_file():
        return json.loads(saved.read_text())
    if run.exists():
        shutil.rmtree(run)
    run.parent.mkdir(parents=True, exist_ok=True)
    proc = _timed([sys.executable, "-m", "research.bench.bench_mapping", "--sfm-child", str(photos), str(run),
                   str(steps), "--sift-upsample-below", str(below), *extra], work / f"{name}.log")
    rec: dict = {"name": name, "sift_upsample_below": below, "options": extra, "process": proc}
    if proc["rc"] == 0:
        st = json.loads((run / "sfm" / "stage.json").read_text())
        s = st["stats"]
        rec.update({"timings": st.get("timings"), "sift": s.get("sift"), "features_median": features_median(run),
                    "n_kept": s["n_kept"], "n_registered": s.get("n_registered"),
                    "model_sizes": s.get("model_sizes"), "n_pairs_verified": s.get("n_pairs_verified"),
                    "steps": json.loads(steps.read_text())["steps"]})
    saved.write_text(json.dumps(rec))
    return rec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("photos", type=Path)
    ap.add_argument("--work", type=Path, required=True)
    ap.add_argument("--settings", type=int, nargs="+", default=[100_000, 1000],
                    help="values of --sift-upsample-below, one run each (100000: COLMAP's, always doubled)")
    ap.add_argument("--truth", type=Path, help="a shared set with ground truth (research.datasets) or a rendered "
                    "capture's frame folder (truth.npy, with --kind)")
    ap.add_argument("--kind", default="object", help="the rendered capture's kind (research.bench.bench_mapping)")
    ap.add_argument("--reuse", action="store_true", help="read a setting's earlier run in WORK instead of running "
                    "it again (its times are that run's)")
    ap.add_argument("--sfm-args", nargs="*", default=[], help="more `curate sfm` flags, every run")
    a = ap.parse_args(argv)
    from curate.sfm.io import load_sfm
    from research.bench.bench_mapping import pose_record, truth_cameras
    from research.datasets import load_ground_truth
    truth = None
    if a.truth is not None:
        truth = truth_cameras(a.truth, a.kind) if (a.truth / "truth.npy").is_file() else load_ground_truth(a.truth)
    out: dict = {"photos": str(a.photos), "runs": []}
    for below in a.settings:
        rec = one(a.work, a.photos, below, a.sfm_args, a.reuse)
        if rec["process"]["rc"] == 0:
            cams = load_sfm(a.work / "runs" / rec["name"]).cameras
            if truth is not None:
                rec["against_truth"] = pose_record(cams, truth)
            first = a.work / "runs" / f"below{a.settings[0]}"
            if below != a.settings[0] and (first / "sfm" / "cameras.json").is_file():
                rec["against_first"] = pose_record(cams, load_sfm(first).cameras)
        out["runs"].append(rec)
        print(json.dumps(rec), file=sys.stderr, flush=True)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
