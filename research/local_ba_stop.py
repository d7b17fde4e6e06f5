"""When each new photo's local bundle adjustment stops: a run folder's own matches mapped by the product's mapper
(`curate.sfm.reconstruction.incremental_options`, `curate.sfm.mapping.incremental_mapping`, one thread) with COLMAP's
local adjustment (``base``: at most 25 Ceres iterations, no function tolerance, so it stops at the iteration cap or a
small gradient) and with variants set as ``NAME:FIELD=VALUE[,FIELD=VALUE]`` on ``pycolmap.IncrementalPipelineOptions``
(``ftol6:ba_local_function_tolerance=1e-6``, ``it10:ba_local_max_num_iterations=10``,
``img4:mapper.ba_local_num_images=4``). Prints one JSON row per mapping: CPU and wall seconds, the models' sizes, the
largest model against the base's (rotation median / max deg, centres relative to the extent) and, with a truth,
against it (an office case's truth file of `research.flip make`, or a rendered capture's frame folder with
``truth.npy``). docs/investigations/sfm.md#local-ba-stop.

    python -m research.local_ba_stop RUN [RUN:CASE.truth.json | RUN=FRAMES ...] \
        --variants ftol6:ba_local_function_tolerance=1e-6 [--office ../shared/data/office] [--work W] [--rows FILE]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from curate.sfm.matching import copy_database


def map_variant(run: Path, work: Path, sets: dict) -> tuple[dict, object]:
    """(the row, the largest model) of ``run``'s matches mapped with the options ``sets`` changed."""
    from curate.sfm import mapping
    from curate.sfm.config import SfmConfig
    from curate.sfm.reconstruction import expected_observations, incremental_options
    sfm = run / "sfm"
    work.mkdir(parents=True, exist_ok=True)
    db = work / "database.db"
    copy_database(sfm / "database.db", db)
    n = sum(1 for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept")
    cfg = SfmConfig()
    opts = incremental_options(cfg, n, expected_observations(db, cfg.min_num_matches))
    for k, v in sets.items():              # FIELD or SUB.FIELD (mapper.ba_local_num_images)
        *path, field = k.split(".")
        obj = opts
        for part in path:
            obj = getattr(obj, part)
        setattr(obj, field, type(getattr(obj, field))(v))
        if path:
            setattr(opts, path[0], obj)      # in case the binding handed back a copy of the nested options
    t, c = time.perf_counter(), time.process_time()
    models = mapping.incremental_mapping(db, sfm / "images", work / "sparse", opts,
                                         repeat_final_refinement=cfg.repeat_final_refinement)
    wall, cpu = time.perf_counter() - t, time.process_time() - c
    best = max(models.values(), key=lambda r: r.num_reg_images())
    return {"cpu_s": round(cpu, 1), "wall_s": round(wall, 1),
            "sizes": sorted((int(r.num_reg_images()) for r in models.values()), reverse=True),
            "points": int(best.num_points3D())}, best


def main(argv=None) -> list[dict]:
    from curate.sfm.model import cameras_from_reconstruction
    from research.bench.bench_mapping import pose_record, truth_cameras
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", help="RUN, RUN:CASE.truth.json (an office case) or RUN=FRAMES (rendered)")
    ap.add_argument("--variants", nargs="*", default=[], help="NAME:FIELD=VALUE[,FIELD=VALUE]")
    ap.add_argument("--office", type=Path, default=Path("../shared/data/office"))
    ap.add_argument("--kind", default="object", help="a rendered capture's kind (research.bench.bench_mapping)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/local_ba_stop"))
    ap.add_argument("--rows", type=Path, help="append the rows here too (JSON lines)")
    a = ap.parse_args(argv)
    variants = {"base": {}}
    for v in a.variants:
        name, _, sets = v.partition(":")
        variants[name] = dict(s.split("=", 1) for s in sets.split(","))
    rows = []
    for spec in a.runs:
        run_s, truth_s, kind = spec, None, None
        if "=" in spec:
            run_s, truth_s = spec.split("=", 1)
            kind = "frames"
        elif ":" in spec:
            run_s, truth_s = spec.split(":", 1)
            kind = "office"
        run = Path(run_s)
        base_cams = None
        for name, sets in variants.items():
            row, best = map_variant(run, a.work / "_".join(run.resolve().parts[-3:]) / name, sets)
            row = {"run": str(run), "variant": name, "sets": sets, **row}
            cams = cameras_from_reconstruction(best, warn=False)[0]
            if kind == "office":
                from research.join_shared import summary, truth_errors
                recs = [r for r in json.loads((run / "sfm" / "images.json").read_text())["photos"]
                        if r["status"] == "kept"]
                row["truth"] = summary(truth_errors(best, recs, json.loads(Path(truth_s).read_text()),
                                                    a.office).values())
            elif kind == "frames":
                row["truth"] = pose_record(cams, truth_cameras(Path(truth_s), a.kind), 4)
            if base_cams is None:
                base_cams = cams
            else:
                row["against_base"] = pose_record(cams, base_cams, 4)
                row["same_photos_as_base"] = set(cams.names) == set(base_cams.names)
            rows.append(row)
            print(json.dumps(row), flush=True)
            if a.rows:
                with open(a.rows, "a") as f:
                    f.write(json.dumps(row) + "\n")
    return rows


if __name__ == "__main__":
    main()
