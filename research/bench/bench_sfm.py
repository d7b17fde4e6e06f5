#!/usr/bin/env python
"""Benchmark the SfM stage on sample folders, against ground-truth poses where there are some.

    python3 -m research.bench.bench_sfm --data ../shared/data/fox ../shared/data/office [--matcher sequential] ...

Runs ``curate.sfm.colmap.run_sfm`` at the default config (overridable below) on each folder
(photos: ``FOLDER/images`` when it exists, else ``FOLDER``), compares the registered
cameras with ``research.datasets.load_ground_truth`` (fox: transforms.json, templering:
templeR_par.txt, office: poses.txt + K.txt) after a similarity alignment, and prints
one line per data set and, as the LAST line, one JSON object ``{name: result}``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import time
from pathlib import Path


from research.align import pose_errors  # noqa: E402
from research.datasets import image_folder, load_ground_truth  # noqa: E402
from curate.sfm.colmap import run_sfm  # noqa: E402
from curate.sfm.config import SfmConfig  # noqa: E402
from curate.sfm.io import load_sfm  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", nargs="+", required=True, help="sample folders (fox, templering, office, skull...)")
    ap.add_argument("--runs", default="/tmp/curate_bench", help="parent of the run folders (one per data set)")
    ap.add_argument("--force", action="store_true", help="rerun even when the stage is up to date")
    ap.add_argument("--tag", default="", help="suffix of the run folder name (to keep variants apart)")
    ap.add_argument("--set", nargs="*", default=[], metavar="FIELD=VALUE",
                    help="SfmConfig overrides, e.g. matcher=sequential max_image_size=800")
    ap.add_argument("-v", "--verbose", action="store_true")
    a = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO if a.verbose else logging.WARNING, format="%(message)s")
    types = {f.name: f.type for f in dataclasses.fields(SfmConfig)}
    over = {}
    for kv in a.set:
        k, v = kv.split("=", 1)
        if k not in types:
            ap.error(f"unknown SfmConfig field {k}")
        t = str(types[k])
        over[k] = (v.lower() in ("1", "true", "yes")) if t == "bool" else int(v) if t == "int" else \
            float(v) if t == "float" else v
    cfg = SfmConfig(**over)
    results = {}
    for folder in map(Path, a.data):
        name = folder.resolve().name
        run = Path(a.runs) / (name + (f"_{a.tag}" if a.tag else ""))
        t0 = time.perf_counter()
        res: dict = {"overrides": over}
        try:
            run_sfm(cfg, image_folder(folder), run, force=a.force)
        except Exception as e:  # noqa: BLE001 - report and go on with the next data set
            res["error"] = f"{type(e).__name__}: {e}"
            results[name] = res
            print(name, "FAILED:", res["error"], flush=True)
            continue
        res["wall_s"] = round(time.perf_counter() - t0, 1)
        stage = json.loads((run / "sfm" / "stage.json").read_text())
        st = stage["stats"]
        res.update({k: st.get(k) for k in ("n_kept", "n_registered", "registered_fraction", "n_points",
                                           "mean_reprojection_error_px", "matcher", "camera_mode", "model_sizes")})
        res["stage_seconds"] = stage["seconds"]
        res["timings"] = stage["timings"]
        gt = load_ground_truth(folder)
        if gt is not None:
            e = pose_errors(load_sfm(run).cameras, gt)
            res.update({k: e[k] for k in ("n_matched", "rotation_deg_median", "rotation_deg_max",
                                          "centre_rel_median", "centre_rel_max")})
            res["registered_of_gt"] = e["n_matched"] / len(gt)
        results[name] = res
        print(name, json.dumps(res), flush=True)
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
