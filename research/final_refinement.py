"""The incremental mapper's last refinement: a run folder's own matches mapped by curate's step-by-step loop
(`curate.sfm.mapping.incremental_mapping`) with COLMAP's repeated final refinement (``colmap``) and without it
(``once``, the product's default): CPU seconds, global refinements run, the models' sizes, the largest model's
poses against each other and, with a truth file of an office case, against the truth. Prints one JSON row per
mapping and one per comparison (docs/investigations/sfm.md#final-refinement).

    python -m research.final_refinement RUN [--truth CASE.truth.json --office ../shared/data/office] [--work W]
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from pathlib import Path
from curate.sfm.matching import copy_database


def map_once(run: Path, work: Path, repeat: bool) -> tuple[dict, object]:
    """(the row, the largest model) of one mapping of ``run``'s matches, on a copy of its database."""
    from curate.sfm import mapping
    from curate.sfm.config import SfmConfig
    from curate.sfm.reconstruction import expected_observations, incremental_options
    sfm = run / "sfm"
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    db = work / "database.db"
    copy_database(sfm / "database.db", db)
    n = sum(1 for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept")
    cfg = SfmConfig()
    opts = incremental_options(cfg, n, expected_observations(db, cfg.min_num_matches))
    calls: list = []
    real = mapping._Loop.global_refinement
    mapping._Loop.global_refinement = lambda self, *a: calls.append(1) or real(self, *a)
    try:
        t, c = time.perf_counter(), time.process_time()
        models = mapping.incremental_mapping(db, sfm / "images", work / "sparse", opts, repeat_final_refinement=repeat)
        wall, cpu = time.perf_counter() - t, time.process_time() - c
    finally:
        mapping._Loop.global_refinement = real
    best = max(models.values(), key=lambda r: r.num_reg_images())
    return {"run": run.name, "variant": "colmap" if repeat else "once", "cpu_s": round(cpu, 1),
            "wall_s": round(wall, 1), "global_refinements": len(calls),
            "sizes": sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)}, best


def main(argv=None) -> list[dict]:
    from curate.sfm.model import cameras_from_reconstruction
    from research.align import pose_errors
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--truth", type=Path, help="an office case's truth file (research.flip make)")
    ap.add_argument("--office", type=Path, default=Path("../shared/data/office"))
    ap.add_argument("--work", type=Path, default=Path("/tmp/final_refinement"))
    a = ap.parse_args(argv)
    rows, best = [], {}
    for repeat in (True, False):
        row, best[repeat] = map_once(a.run, a.work / a.run.name / ("colmap" if repeat else "once"), repeat)
        if a.truth:
            from research.join_shared import summary, truth_errors
            recs = [r for r in json.loads((a.run / "sfm" / "images.json").read_text())["photos"]
                    if r["status"] == "kept"]
            row["truth"] = summary(truth_errors(best[repeat], recs, json.loads(a.truth.read_text()), a.office).values())
        rows.append(row)
        print(json.dumps(row), flush=True)
    cams = {k: cameras_from_reconstruction(r, warn=False)[0] for k, r in best.items()}
    e = pose_errors(cams[False], cams[True])
    row = {"run": a.run.name, "once_vs_colmap": {k: round(e[k], 4) for k in ("rotation_deg_median", "rotation_deg_max",
                                                                              "centre_rel_median", "centre_rel_max")},
           "same_photos": set(cams[False].names) == set(cams[True].names)}
    rows.append(row)
    print(json.dumps(row), flush=True)
    return rows


if __name__ == "__main__":
    main()
