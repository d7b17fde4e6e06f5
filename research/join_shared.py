"""Each split part of a capture joined to its largest by the frames they share (:func:`curate.sfm.parts.join_shared`),
one part at a time, judged against the truth: how far the shared frames disagree once aligned, what the stage's rule
decides, and how far the frames the join adds lie from the truth in the joined model (a right join adds frames
within 5 deg, median). Prints one JSON row per part.

    python -m research.join_shared CASE=RUN[:SPARSE] ... --truth-dir /tmp/w/flip [--office ../shared/data/office]
        [--adjust] [--label L]

``RUN``: a run folder (its ``sfm/database.db``, ``sfm/images.json``); ``SPARSE``: the folder of the parts' models
(default ``RUN/sfm/sparse``); the truth is ``TRUTH_DIR/CASE.truth.json`` (:mod:`research.takes`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def truth_errors(rec, recs: list[dict], tj: dict, office: Path) -> dict[str, float]:
    """{working name: orientation error in degrees} of ``rec``'s registered frames against the truth, after
    one similarity of the centres (:func:`research.takes.errors_against_truth`)."""
    from curate.sfm.model import cameras_from_reconstruction
    from research.takes import errors_against_truth, truth_of
    cams = cameras_from_reconstruction(rec, warn=False)[0]
    e = errors_against_truth(cams, recs, tj, office)
    if e is None:
        return {}
    gt = truth_of(recs, tj)
    named = [n for n in cams.names if n in gt]
    return dict(zip(named, e["rotation_deg"]))


def summary(x) -> dict | None:
    x = np.asarray(list(x), float)
    if not len(x):
        return None
    return {"n": int(len(x)), "median": round(float(np.median(x)), 2), "max": round(float(x.max()), 2),
            "over5": int((x > 5).sum())}


def run_case(case: str, run: Path, sparse: Path, tj: dict, office: Path, max_rot_deg: float,
             adjust: bool = False) -> list[dict]:
    import pycolmap

    from curate.sfm.parts import join_shared
    recs = [r for r in json.loads((run / "sfm/images.json").read_text())["photos"] if r["status"] == "kept"]
    parts = sorted((pycolmap.Reconstruction(str(p)) for p in sorted(sparse.iterdir()) if p.is_dir()),
                   key=lambda r: -r.num_reg_images())
    rows = []
    base = truth_errors(parts[0], recs, tj, office)
    for k, part in enumerate(parts[1:], 1):
        row = {"case": case, "largest": int(parts[0].num_reg_images()), "part": k,
               "photos": int(part.num_reg_images()), "largest_truth": summary(base.values())}
        _, _, decided = join_shared({0: parts[0], 1: part}, max_rot_deg)
        joined, _, _ = join_shared({0: parts[0], 1: part}, np.inf, np.inf)   # every part that can be aligned
        row.update(shared=decided[0]["shared"], rot_deg=decided[0]["rot_deg"], step=decided[0]["step"],
                   joined_by_rule=decided[0]["joined"])
        if joined is not None:
            err = truth_errors(joined, recs, tj, office)
            new = {im.name for im in (part.image(i) for i in part.reg_image_ids())} - set(base)
            row["added_truth"] = summary(err[n] for n in new if n in err)
            row["joined_truth"] = summary(err.values())
            row["right"] = bool(row["added_truth"] and row["added_truth"]["median"] <= 5)
        rows.append(row)
    joined, ids, _ = join_shared(dict(enumerate(parts)), max_rot_deg)   # all parts, as the stage joins them
    row = {"case": case, "part": "all", "models": [int(p.num_reg_images()) for p in parts], "joined_parts": ids,
           "largest_truth": summary(base.values())}
    if joined is not None:
        err = truth_errors(joined, recs, tj, office)
        row.update(joined_photos=int(joined.num_reg_images()), joined_truth=summary(err.values()),
                   added_truth=summary(v for n, v in err.items() if n not in base))
    if adjust and joined is not None:   # the stage's join (triangulated, poses held), then one bundle adjustment
        import tempfile
        import time

        from curate.sfm.config import SfmConfig
        from curate.sfm.reconstruction import join_split
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            rec = join_split(SfmConfig(progress=False, max_part_disagreement_deg=max_rot_deg), run / "sfm/database.db",
                             run / "sfm/images", Path(tmp), dict(enumerate(parts)), {})[0]
            row["triangulated"] = {"seconds": round(time.perf_counter() - t, 2), "points": int(rec.num_points3D()),
                                   "points_before": int(parts[0].num_points3D()),
                                   "truth": summary(truth_errors(rec, recs, tj, office).values())}
            t = time.perf_counter()
            ba = pycolmap.BundleAdjustmentOptions()
            ba.refine_principal_point = False
            ba.ceres.solver_options.num_threads = 1
            pycolmap.bundle_adjustment(rec, ba)
            row["adjusted"] = {"seconds": round(time.perf_counter() - t, 2),
                               "truth": summary(truth_errors(rec, recs, tj, office).values())}
    rows.append(row)
    return rows


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", help="CASE=RUN[:SPARSE]")
    ap.add_argument("--truth-dir", type=Path, required=True)
    ap.add_argument("--office", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/office")
    ap.add_argument("--max-rot-deg", type=float, default=3.0, help="SfmConfig.max_part_disagreement_deg")
    ap.add_argument("--label", default="", help="written into every row")
    ap.add_argument("--adjust", action="store_true", help="also triangulate the joined model as the stage does "
                    "(curate.sfm.reconstruction.join_split) and adjust it once: truth and seconds of both")
    a = ap.parse_args(argv)
    out = []
    for spec in a.cases:
        case, where = spec.split("=", 1)
        run, _, sparse = where.partition(":")
        tj = json.loads((a.truth_dir / f"{case}.truth.json").read_text())
        rows = run_case(case, Path(run), Path(sparse) if sparse else Path(run) / "sfm/sparse", tj, a.office,
                        a.max_rot_deg, a.adjust)
        for r in rows:
            print(json.dumps({"label": a.label, **r} if a.label else r), flush=True)
        out += rows
    return out


if __name__ == "__main__":
    main()
