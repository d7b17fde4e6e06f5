"""Which frames the steps their own matches refute would blame (``curate.sfm.continuity.lone_refuted``), in run
folders already mapped, and how far those frames are from the truth.

    python -m research.step_blame RUN[:CASE.truth.json] ... [--office ../shared/data/office] [--rows FILE]

Each model of the run folder (``sfm/sparse/K``) is checked step by step (``step_fits``, as the stage checks it); a
row per model: frames, steps checked and refuted, the frames blamed and, with a truth (``research.flip make``'s
``CASE.truth.json``), each blamed frame's orientation error and the model's frames over 5 deg after one similarity
of the centres (``research.join_shared.truth_errors``; office cases need ``--office``).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path



def blame(run: Path, truth: Path | None, office: Path | None) -> list[dict]:
    import pycolmap

    from curate.sfm.continuity import STEP_MIN_SHARE, lone_refuted, step_fits
    from research.join_shared import truth_errors
    from research.path_check import kept_records
    from research.rundb import database_copy
    kept = kept_records(run)
    recs = [r for r in json.loads((run / "sfm" / "images.json").read_text())["photos"] if r["status"] == "kept"]
    tj = json.loads(truth.read_text()) if truth else None
    rows = []
    with database_copy(run / "sfm" / "database.db") as db:   # opening the run's own would rewrite it
        models = [(m, pycolmap.Reconstruction(m)) for m in sorted((run / "sfm" / "sparse").iterdir())]
        fits_of = {m.name: step_fits(rec, kept, db) for m, rec in models}
    for model, rec in models:
        fits = fits_of[model.name]
        blamed = {tk: lone_refuted(steps) for tk, steps in fits.items()}
        row = {"run": str(run), "model": model.name, "frames": int(rec.num_reg_images()),
               "checked": sum(map(len, fits.values())),
               "refuted": sum(f < STEP_MIN_SHARE for s in fits.values() for *_, f in s),
               "blamed": sorted(n for v in blamed.values() for n in v)}
        if tj is not None:
            err = truth_errors(rec, recs, tj, office)
            if err:
                row["blamed_deg"] = [round(err[n], 2) if n in err else None for n in row["blamed"]]
                row["over_5"] = sum(e > 5 for e in err.values())
                row["over_5_not_blamed"] = sorted(n for n, e in err.items() if e > 5 and n not in row["blamed"])
        rows.append(row)
    return rows


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="RUN or RUN:CASE.truth.json")
    ap.add_argument("--office", type=Path, default=None)
    ap.add_argument("--rows", type=Path, default=None, help="append each row as a JSON line")
    a = ap.parse_args(argv)
    out = []
    for arg in a.runs:
        run, _, truth = arg.partition(":")
        for row in blame(Path(run), Path(truth) if truth else None, a.office):
            print(json.dumps(row), flush=True)
            out.append(row)
            if a.rows:
                with a.rows.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    return out


if __name__ == "__main__":
    main()
