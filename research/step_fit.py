"""Each step between consecutive frames of a finished SfM run's models against the frames' own verified matches:
the share of a step's matches its relative pose in the model explains (`curate.sfm.continuity.step_fits`),
with the frames' orientation errors against a truth where one is given (after one similarity of the centres: a
short part's errors are those of a poorly fixed similarity). One JSON line per model and take.

Reads ``RUN/sfm/images.json``, ``RUN/sfm/database.db`` and every model under ``RUN/sfm/sparse/``.

    python -m research.step_fit RUN[:CASE.truth.json] ... --office ../shared/data/office [--rows FILE]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


NEAR = 0.7
"""Steps under this fit are listed with their frames' errors against the truth (``steps_under_0.7``: from, to, fit,
inliers, deg, deg): how close to the limit the sound steps come."""


def _deg(x) -> float | None:
    return None if x is None else round(float(x), 1)


def check(run: Path, truth: Path | None, office: Path | None) -> list[dict]:
    import pycolmap

    from curate.sfm.continuity import STEP_MIN_SHARE, step_fits
    from research.join_shared import truth_errors
    from research.path_check import kept_records
    from research.rundb import database_copy
    kept = kept_records(run)
    recs = [r for r in json.loads((run / "sfm/images.json").read_text())["photos"] if r["status"] == "kept"]
    rows = []
    with database_copy(run / "sfm/database.db") as db:   # one copy for every model
        models = [(sp, pycolmap.Reconstruction(str(sp)))
                  for sp in sorted(p for p in (run / "sfm/sparse").iterdir() if p.is_dir())]
        fits = {sp.name: step_fits(rec, kept, db) for sp, rec in models}
    for sp, rec in models:
        err = truth_errors(rec, recs, json.loads(truth.read_text()), office) if truth else {}
        e = np.array(list(err.values()), float)
        for take, steps in fits[sp.name].items():
            st = [{"from": a, "to": b, "inliers": n, "fit": round(f, 2)} for a, b, n, f in steps]
            fit = np.array([s["fit"] for s in st], float)
            low = [s for s in st if s["fit"] < STEP_MIN_SHARE]
            near = [[s["from"], s["to"], s["fit"], s["inliers"], _deg(err.get(s["from"])), _deg(err.get(s["to"]))]
                    for s in st if s["fit"] < NEAR]
            rows.append({"run": str(run), "model": sp.name, "frames": rec.num_reg_images(), "take": take,
                         "steps": len(st), "fit_min": float(fit.min()),
                         "fit_p5": round(float(np.percentile(fit, 5)), 3),
                         "fit_median": round(float(np.median(fit)), 3), "unexplained": len(low),
                         "unexplained_steps": [[s["from"], s["to"], s["fit"], s["inliers"]] for s in low],
                         "steps_under_0.7": near,
                         **({"truth_median_deg": round(float(np.median(e)), 2), "truth_over5": int((e > 5).sum()),
                             "truth_n": int(len(e))} if len(e) else {})})
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="RUN or RUN:CASE.truth.json")
    ap.add_argument("--office", type=Path, default=None, help="the office set (for a truth's poses)")
    ap.add_argument("--rows", type=Path, default=None, help="append the rows to this JSONL file")
    a = ap.parse_args(argv)
    for spec in a.runs:
        run, _, truth = spec.partition(":")
        for row in check(Path(run), Path(truth) if truth else None, a.office):
            print(json.dumps(row))
            if a.rows:
                with a.rows.open("a") as f:
                    f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
