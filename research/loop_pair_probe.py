"""One loop pair can bend a stretch of a walk: the verified loop pairs of a run with their two-view configuration and
the truth's relative pose, and the run's matches mapped again without the loop pairs between two ranges of frames
(truth index), each frame's orientation error against the truth. Prints JSON.

    python -m research.loop_pair_probe RUN CASE.truth.json --office ../shared/data/office \\
        --drop 333-347:0-299 --show 336-348 --work W
    python -m research.loop_pair_probe RUN CASE.truth.json --office ../shared/data/office \\
        --drop-far-sequential 64 --work W   # the sequential neighbours 64 frames apart or more that loop detection
                                            # did not list, left out (docs/investigations/sfm.md#sequential-neighbours)
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def _span(text: str) -> tuple[int, int]:
    a, b = text.split("-")
    return int(a), int(b)


def main(argv=None) -> dict:
    import pycolmap

    from curate.core.cameras import rotation_angle_deg
    from curate.sfm.config import SfmConfig
    from curate.sfm.reconstruction import map_incremental
    from research.datasets import load_office
    from research.join_shared import truth_errors
    from curate.sfm.matching import copy_database
    from research.takes import truth_of
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("truth", type=Path)
    ap.add_argument("--office", type=Path, required=True)
    ap.add_argument("--drop", default=None, help="A-B:C-D: leave out the loop pairs between these frame ranges")
    ap.add_argument("--drop-planar", action="store_true", help="leave out every planar-or-panoramic loop pair (4-6)")
    ap.add_argument("--drop-far-sequential", type=int, default=0, metavar="D",
                    help="leave out the sequential pairs at least D frames apart that are not loop pairs")
    ap.add_argument("--show", default="0-100000", help="frames (truth index) whose errors are printed")
    ap.add_argument("--work", type=Path, required=True)
    a = ap.parse_args(argv)
    sfm = a.run / "sfm"
    tj = json.loads(a.truth.read_text())
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    gt = truth_of(recs, tj)
    truth = load_office(a.office)
    loop = [tuple(ln.split()) for ln in (sfm / "loop_pairs.txt").read_text().splitlines() if ln.strip()]
    out: dict = {"run": str(a.run), "drop": a.drop}
    rows = []
    from research.rundb import database_copy
    with database_copy(sfm / "database.db") as copy, pycolmap.Database.open(copy) as d:
        ids = {im.name: im.image_id for im in d.read_all_images()}
        for x, y in loop:
            if not d.exists_two_view_geometry(ids[x], ids[y]):
                continue
            g = d.read_two_view_geometry(ids[x], ids[y])
            if len(g.inlier_matches) < SfmConfig().min_num_matches:
                continue
            tx, ty = gt[x], gt[y]
            turn = rotation_angle_deg(truth.rotations[ty].T @ truth.rotations[tx])
            rows.append({"frames": [tx, ty], "inliers": int(len(g.inlier_matches)), "config": int(g.config),
                         "truth_rot_deg": round(float(turn), 1),
                         "truth_dist": round(float(np.linalg.norm(truth.centres[tx] - truth.centres[ty])), 2)})
    out["verified_loop_pairs"] = len(rows)
    out["by_config"] = {str(c): sum(r["config"] == c for r in rows) for c in sorted({r["config"] for r in rows})}
    lo, hi = _span(a.show)
    if a.drop or a.drop_planar or a.drop_far_sequential:
        if a.drop_far_sequential:
            order = {n: i for i, n in enumerate(sorted(ids))}
            listed = {tuple(sorted(p)) for p in loop}
            seq = [tuple(ln.split()) for ln in (sfm / "sequential_pairs.txt").read_text().splitlines() if ln.strip()]
            cut = [(x, y) for x, y in seq if abs(order[x] - order[y]) >= a.drop_far_sequential
                   and tuple(sorted((x, y))) not in listed]
            out["dropped"] = len(cut)
        elif a.drop:
            (p0, p1), (q0, q1) = (_span(s) for s in a.drop.split(":"))
            inside = lambda t, s0, s1: s0 <= t <= s1  # noqa: E731
            cut = [(x, y) for x, y in loop if (inside(gt[x], p0, p1) and inside(gt[y], q0, q1))
                   or (inside(gt[y], p0, p1) and inside(gt[x], q0, q1))]
            out["dropped"] = [r for r in rows if (inside(r["frames"][0], p0, p1) and inside(r["frames"][1], q0, q1))
                              or (inside(r["frames"][1], p0, p1) and inside(r["frames"][0], q0, q1))]
        else:
            planar = {tuple(r["frames"]) for r in rows if r["config"] in (4, 5, 6)}
            cut = [(x, y) for x, y in loop if (gt[x], gt[y]) in planar]
            out["dropped"] = len(cut)
        a.work.mkdir(parents=True, exist_ok=True)
        db = a.work / "database.db"
        copy_database(sfm / "database.db", db)
        with pycolmap.Database.open(db) as d:
            for x, y in cut:
                if d.exists_two_view_geometry(ids[x], ids[y]):
                    d.delete_two_view_geometry(ids[x], ids[y])
                d.delete_matches(ids[x], ids[y])
        (a.work / "sparse").mkdir(exist_ok=True)
        models = map_incremental(SfmConfig(progress=False), db, sfm / "images", a.work / "sparse", len(ids), False)
        out["models_without"] = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
        rec = max(models.values(), key=lambda r: r.num_reg_images())
    else:
        rec = pycolmap.Reconstruction(str(sfm / "sparse" / "0"))
    err = truth_errors(rec, recs, tj, a.office)
    vals = np.asarray(list(err.values()))
    out["truth"] = {"n": int(len(vals)), "median": round(float(np.median(vals)), 2), "over5": int((vals > 5).sum())}
    out["shown"] = {gt[n]: round(e, 1) for n, e in sorted(err.items(), key=lambda kv: gt[kv[0]]) if lo <= gt[n] <= hi}
    print(json.dumps(out))
    return out


if __name__ == "__main__":
    main()
