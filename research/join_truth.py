"""The join rule's two error rates on captures with truth (issue 58, item 2).

For run folders whose SfM stage finished on a capture written by :mod:`research.flip` (its ``<case>.truth.json``
beside the capture), maps the run's matches again with :func:`curate.sfm.reconstruction.map_capture` (the
default options: incremental, and the global mapper where the incremental mapper split) and measures against
the truth every model it saw: each incremental part, the global model as COLMAP returned it, and the model the
rule kept. A model is *right* when at most 5% of its frames are over 5 deg from the truth (after one similarity
of the centres, :func:`research.align.pose_errors`).

The two errors of the rule, per run that split:

* **a correct join refused**: the global model was right and held more frames than the largest part, and the
  rule kept the incremental part;
* **a wrong part kept**: the model the rule kept is not right (a global model that bent a part, or an incremental
  part that is itself wrong).

    python3 -m research.join_truth /tmp/w/flip/runs/base1/half_t-1_0:/tmp/w/flip/half.truth.json ... \\
        --office ../shared/data/office --log /tmp/w/join.jsonl
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from curate.sfm.matching import copy_database

RIGHT_MAX_OVER_5 = 0.05
"""A model is right when at most this share of its frames is over 5 deg from the truth."""


def _errors(rec, recs: list, truth: dict, office: Path) -> dict:
    from curate.sfm.model import cameras_from_reconstruction
    from research.takes import errors_against_truth
    cams = cameras_from_reconstruction(rec, warn=False)[0]
    e = errors_against_truth(cams, recs, truth, office)
    if e is None:
        return {"frames": len(cams.names), "with_truth": 0}
    over = int(sum(r > 5 for r in e["rotation_deg"]))
    return {"frames": len(cams.names), "with_truth": len(e["rotation_deg"]),
            "rotation_deg_median": round(float(e["rotation_deg_median"]), 2), "over_5_deg": over,
            "centre_rel_median": round(float(e["centre_rel_median"]), 4),
            "right": over <= RIGHT_MAX_OVER_5 * len(e["rotation_deg"])}


def one(run: Path, truth_json: Path, office: Path) -> dict:
    """Map ``run``'s matches again as the stage does; every model measured against the truth."""
    from curate.sfm import reconstruction as recon
    from curate.sfm.config import SfmConfig
    sfm = run / "sfm"
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    truth = json.loads(truth_json.read_text())
    seen: dict = {}
    orig_inc, orig_glob = recon.map_incremental, recon.map_global

    def inc(*a, **k):
        models = orig_inc(*a, **k)
        seen["incremental"] = [_errors(r, recs, truth, office) for r in
                               sorted(models.values(), key=lambda r: -r.num_reg_images())]
        return models

    def glob(*a, **k):
        models = orig_glob(*a, **k)
        seen["global"] = [_errors(r, recs, truth, office) for r in
                          sorted(models.values(), key=lambda r: -r.num_reg_images())][:1]
        return models

    cfg = SfmConfig(progress=False)
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "database.db"
        copy_database(sfm / "database.db", db)
        recon.map_incremental, recon.map_global = inc, glob
        stats: dict = {}
        t = time.perf_counter()
        try:
            kept = recon.map_capture(cfg, db, sfm / "images", Path(tmp) / "mapper", len(recs), stats)
        finally:
            recon.map_incremental, recon.map_global = orig_inc, orig_glob
        best = max(kept.values(), key=lambda r: r.num_reg_images())
        out = {"run": str(run), "frames": len(recs), "mapper": stats.get("mapper"),
               "kept": _errors(best, recs, truth, office), **seen,
               "global_decision": (stats.get("mappers_tried") or {}).get("global", {}),
               "seconds": round(time.perf_counter() - t, 1)}
    g = (out.get("global") or [None])[0]
    largest = out["incremental"][0]["frames"] if out.get("incremental") else 0
    out["split"] = "global" in out
    out["correct_join_refused"] = bool(g and g.get("right") and g["frames"] > largest
                                       and out["mapper"] == "incremental")
    out["wrong_part_kept"] = not out["kept"].get("right", True)
    for k in ("verified",):
        out["global_decision"].pop(k, None)
    return out


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="RUN:TRUTH_JSON pairs")
    ap.add_argument("--office", type=Path, required=True)
    ap.add_argument("--log", type=Path, required=True)
    a = ap.parse_args(argv)
    rows = []
    for pair in a.runs:
        run, truth = pair.split(":")
        row = one(Path(run), Path(truth), a.office)
        rows.append(row)
        with a.log.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(json.dumps({k: row[k] for k in ("run", "frames", "mapper", "kept", "split", "correct_join_refused",
                                               "wrong_part_kept", "seconds")}), flush=True)
    split = [r for r in rows if r["split"]]
    summary = {"runs": len(rows), "split": len(split),
               "correct_join_refused": sum(r["correct_join_refused"] for r in split),
               "wrong_part_kept": sum(r["wrong_part_kept"] for r in rows)}
    print(json.dumps(summary))
    return rows


if __name__ == "__main__":
    main()
