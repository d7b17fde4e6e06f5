"""The incremental mapper's options against splits (issue 58, item 2): the same matches mapped with variants.

For each run folder (a finished SfM stage: ``RUN/sfm/database.db``, ``images``, ``images.json``) and each
variant (``NAME:KEY=VALUE,KEY=VALUE``; keys of ``IncrementalPipelineOptions`` as ``opts.x``, of its mapper as
``mapper.x``, of its triangulation as ``tri.x``), maps the matches with curate's incremental options plus the
variant and prints one JSON line: the models, the largest model's frames, seconds, and, with ``--truth``
(the case's ``<case>.truth.json`` of research.flip / research.takes), the median / max rotation error of the
largest model against the office's ground truth and how many frames lie over 5 degrees; for every variant after
the first, how far its largest model's orientations lie from the first's on the frames both hold (90th
percentile and max, deg, once one rotation aligns them). The schedule of global adjustments is the one the
stage chooses for the run's matches (by photos and by the observations they promise).

    python3 -m research.mapper_options /tmp/w/flip/runs/base1/half_t-1_0 --truth /tmp/w/flip/half.truth.json \\
        --variants base: two_view:tri.ignore_two_view_tracks=False
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def parse_variant(s: str) -> tuple[str, dict]:
    name, _, rest = s.partition(":")
    kv = {}
    for item in filter(None, rest.split(",")):
        k, v = item.split("=")
        kv[k] = {"True": True, "False": False}.get(v, None)
        if kv[k] is None:
            kv[k] = float(v) if "." in v or "e" in v else int(v)
    return name, kv


def apply(opts, kv: dict) -> None:
    for k, v in kv.items():
        where, _, attr = k.partition(".")
        obj = {"opts": opts, "mapper": opts.mapper, "tri": opts.triangulation}[where]
        if not hasattr(obj, attr):
            raise ValueError(f"no option {k}")
        setattr(obj, attr, type(getattr(obj, attr))(v))


def main(argv=None) -> list[dict]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+")
    ap.add_argument("--truth", type=Path, nargs="*", default=[], help="one per run (same order)")
    ap.add_argument("--office", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/office")
    ap.add_argument("--variants", nargs="+", default=["base:"])
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    import pycolmap

    from curate.sfm.config import SfmConfig
    from curate.sfm.model import cameras_from_reconstruction
    from curate.core.cameras import rotation_disagreement
    from curate.sfm.reconstruction import expected_observations, incremental_options
    from research.takes import errors_against_truth
    rows = []
    for r_i, run in enumerate(a.runs):
        sfm = run / "sfm"
        truth = json.loads(a.truth[r_i].read_text()) if r_i < len(a.truth) else None
        recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
        n = len(recs)
        n_obs = expected_observations(sfm / "database.db")   # the schedule the stage would choose
        first = None
        for v in a.variants:
            name, kv = parse_variant(v)
            cfg = SfmConfig(progress=False, num_threads=a.threads)
            opts = incremental_options(cfg, n, n_obs)
            apply(opts, kv)
            with tempfile.TemporaryDirectory() as tmp:
                db = Path(tmp) / "db.db"
                copy_database(sfm / "database.db", db)
                pycolmap.set_random_seed(cfg.seed)
                t = time.perf_counter()
                models = pycolmap.incremental_mapping(db, sfm / "images", Path(tmp) / "out", options=opts)
                sec = time.perf_counter() - t
            sizes = sorted((int(m.num_reg_images()) for m in models.values()), reverse=True)
            row = {"run": run.name, "variant": name, "options": kv, "models": sizes, "n": n,
                   "largest": sizes[0] if sizes else 0, "seconds": round(sec, 1)}
            if models:
                best = max(models.values(), key=lambda m: m.num_reg_images())
                cams = cameras_from_reconstruction(best, warn=False)[0]
                if first is None:
                    first = cams
                else:   # against the first variant's largest model, on the frames both hold
                    ia = {nm: i for i, nm in enumerate(first.names)}
                    both = [(ia[nm], i) for i, nm in enumerate(cams.names) if nm in ia]
                    d = rotation_disagreement(first.rotations[[x for x, _ in both]],
                                              cams.rotations[[y for _, y in both]])
                    row.update(vs_first_common=len(both), vs_first_rot_p90=round(float(np.percentile(d, 90)), 3)
                               if len(d) else None, vs_first_rot_max=round(float(d.max()), 3) if len(d) else None)
            if models and truth is not None:
                e = errors_against_truth(cams, recs, truth, a.office)
                if e is not None:
                    row.update(rot_median=round(e["rotation_deg_median"], 2), rot_max=round(e["rotation_deg_max"], 2),
                               over_5=int(sum(x > 5 for x in e["rotation_deg"])))
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


if __name__ == "__main__":
    main()
