"""The incremental mapper on a finished run's matches, again: CPU and wall seconds, model sizes, pose
error and the time of each global refinement, one JSON line (docs/investigations/sfm.md#mapping-past-1000).

    python3 -m research.ba_schedule RUN TRUTH KIND [OPTION=VALUE ...]
    python3 -m research.ba_schedule RUN TRUTH KIND --curate [--first N] [--direct-ba N] [FIELD=VALUE ...]
        [OPTION=VALUE ...]

Without ``--curate``: COLMAP's schedule of global adjustments, or OPTION=VALUE overrides of
pycolmap.IncrementalPipelineOptions (dotted for nested options: ``mapper.ba_global_ignore_redundant_points3D=1``).
With ``--curate``: curate's own mapping (``map_incremental``, as ``curate sfm`` maps) under SfmConfig
FIELD=VALUE overrides, and OPTION=VALUE (names that are no SfmConfig field) set on top (past 1,000 photos
curate's loop, :mod:`curate.sfm.mapping`, choosing each global adjustment's solver by the fill:
``direct_ba_max_fill=0`` keeps Ceres' choice, COLMAP's own); with ``--direct-ba N`` that loop maps with
every global adjustment factored directly up to N photos (COLMAP: 1,000, then iterative). ``--first N`` maps
only the first N photos in name order (a shorter capture from the same
matches). KIND: ``video`` (TRUTH a ground-truth folder such as ../shared/data/office, RUN from its
video), ``walk``, ``hall``, ``hall_back`` or ``grid`` (TRUTH a folder research.bench.bench_mapping rendered of
that capture, with truth.npy) or ``takes``
(TRUTH ``CASE.truth.json:OFFICE``, a case of research.takes and the office folder).

``global_refinements``: [registered frames, seconds] of each global refinement; for curate's loop
timed around each call (and ``global_adjustments``, its choices past 1,000 photos), for COLMAP's pipeline read from the
timestamps of its log (from the refinement's log line to the next registration).
"""
from __future__ import annotations

import dataclasses
import json
import re
import resource
import shutil
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np
from curate.sfm.matching import copy_database


def refinements_from_log(log: Path) -> list[list[float]]:
    """[[registered frames, seconds]] of each "Retriangulation and Global bundle adjustment" in a
    COLMAP log (glog lines ``I20261127 00:01:02.123456 ...``): from its line to the next registration."""
    out, start, frames = [], None, 0
    for line in log.read_text(errors="replace").splitlines():
        m = re.match(r"[IWE](\d{8} \d\d:\d\d:\d\d\.\d+)", line)
        if not m:
            continue
        t = datetime.strptime(m.group(1), "%Y%m%d %H:%M:%S.%f").timestamp()
        if "Retriangulation and Global bundle adjustment" in line:
            start = t
        elif start is not None and ("Registering image" in line or "Keeping" in line or "Discarding" in line):
            out.append([frames, round(t - start, 2)])
            start = None
        r = re.search(r"num_reg_frames=(\d+)", line)
        if r:
            frames = int(r.group(1)) + 1   # the count before this registration
    return out


def path_record(rec, sfm: Path) -> dict:
    """Per video take of the model ``rec``: its largest step as a multiple of the speed around it
    (curate.sfm.continuity.step_ratios) and the one-way jumps ``curate sfm`` would warn of
    (curate.sfm.continuity.jumps_along); ``sfm``: the run's sfm folder (images.json)."""
    from curate.sfm.continuity import frame_times, jumps_along, step_ratios, times_and_centres, video_takes
    from research.path_check import kept_records
    kept = kept_records(sfm.parent)      # PhotoRecords: jumps_along reads numbered photos by their names too
    out = {}
    for take, frames in video_takes(rec, frame_times(kept)).items():
        r = step_ratios(*times_and_centres(frames)) if len(frames) > 1 else np.zeros(0)
        out[take] = {"frames": len(frames), "largest_step_x_around": round(float(r.max()), 2) if len(r) else None}
    return {"takes": out, "jumps": jumps_along(rec, kept)}


def set_option(options, path: str, value: str) -> None:
    """``options.<path> = value`` (pycolmap options; ``path`` dotted for nested ones), the value read
    as the type of the option's current value."""
    *parents, name = path.split(".")
    for p in parents:
        options = getattr(options, p)
    cur = getattr(options, name)
    setattr(options, name, value.lower() in ("1", "true") if isinstance(cur, bool) else type(cur)(float(value)))


def _take(args: list[str], flag: str) -> int | None:
    """The integer after ``flag`` in ``args`` (both removed from it), or None when it is absent."""
    if flag not in args:
        return None
    k = args.index(flag)
    value = int(args[k + 1])
    del args[k:k + 2]
    return value


def main(argv: list[str]) -> dict:
    import pycolmap

    import curate.sfm.mapping as M
    import curate.sfm.reconstruction as C     # incremental_options patched where map_incremental reads it
    from curate.sfm.model import cameras_from_reconstruction
    from curate.sfm.native import colmap_log
    from curate.sfm.config import SfmConfig
    from research.sfm_mappers import sfm_config_overrides
    run, truth, capture, rest = Path(argv[0]), argv[1], argv[2], list(argv[3:])
    curate_mode = "--curate" in rest
    direct, first = _take(rest, "--direct-ba"), _take(rest, "--first")
    pairs = [a for a in rest if a != "--curate"]
    ov = dict(a.split("=", 1) for a in pairs)
    fields = {f.name for f in dataclasses.fields(SfmConfig)} if curate_mode else set()
    colmap_ov = {k: v for k, v in ov.items() if k not in fields}
    sfm = run / "sfm"
    cfg = SfmConfig(progress=False, **sfm_config_overrides([a for a in pairs if a.split("=", 1)[0] in fields]))
    tmp = Path(tempfile.mkdtemp())
    db = tmp / "d.db"
    copy_database(sfm / "database.db", db)
    names = sorted(p.name for p in (sfm / "images").iterdir())[:first]

    orig = C.incremental_options
    if colmap_ov or not curate_mode:
        def patched(cfg, n_images=0):
            o = orig(cfg, n_images if curate_mode else 0)   # curate's or COLMAP's schedule, then the overrides
            for k, v in colmap_ov.items():
                set_option(o, k, v)
            return o
        C.incremental_options = patched
    if first:
        inner = C.incremental_options

        def only_first(cfg, n_images=0):
            o = inner(cfg, n_images)
            o.image_names = names
            return o
        C.incremental_options = only_first
    timed: list = []
    plain = M._Loop.global_refinement

    def timed_refinement(self, pipeline, mapper, mapper_options):
        t = time.perf_counter()
        plain(self, pipeline, mapper, mapper_options)
        timed.append([mapper.reconstruction.num_reg_frames(), round(time.perf_counter() - t, 2)])
    M._Loop.global_refinement = timed_refinement
    adjustments: list = []

    pycolmap.set_random_seed(0)
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    t0 = time.perf_counter()
    with colmap_log(tmp / "colmap.log"):
        if direct:
            opts = C.incremental_options(cfg, len(names))
            ba = opts.get_global_bundle_adjustment()
            ba.ceres.max_num_images_direct_sparse_cpu_solver = direct
            models = M.incremental_mapping(db, sfm / "images", tmp / "m", opts, global_ba=ba)
        else:
            models = C.map_incremental(cfg, db, sfm / "images", tmp / "m", len(names), False, adjustments)
    M._Loop.global_refinement = plain
    r1 = resource.getrusage(resource.RUSAGE_SELF)
    rec = {"run": str(run), "mode": "curate" if curate_mode else "colmap_schedule", "overrides": ov,
           "n_photos": len(names), "wall_s": round(time.perf_counter() - t0, 1),
           "cpu_s": round(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime, 1),
           "peak_rss_mb": round(r1.ru_maxrss / 1024),
           "loop": "curate.sfm.mapping" if timed else "colmap", "direct_ba_up_to": direct or
           pycolmap.BundleAdjustmentOptions().ceres.max_num_images_direct_sparse_cpu_solver,
           "global_refinements": timed or refinements_from_log(tmp / "colmap.log"),
           "global_adjustments": adjustments}
    if capture in ("video", "takes"):
        best = max(models.values(), key=lambda r: r.num_reg_images())
        cams = cameras_from_reconstruction(best, warn=False)[0]
        if capture == "video":
            from research.align import pose_errors
            from research.datasets import load_ground_truth
            from research.sfm_mappers import truth_for, video_frames
            e = pose_errors(*truth_for(cams, load_ground_truth(Path(truth)), video_frames(sfm)[1]))
        else:                     # TRUTH: CASE.truth.json:OFFICE (research.takes make, ../shared/data/office)
            from research.takes import errors_against_truth
            tj, office = str(truth).split(":", 1)
            recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
            e = errors_against_truth(cams, recs, json.loads(Path(tj).read_text()), Path(office))
        rd = np.asarray(e["rotation_deg"])
        rec["path"] = path_record(best, sfm)
        rec.update(model_sizes=sorted((int(r.num_reg_images()) for r in models.values()), reverse=True),
                   rotation_deg_median=round(e["rotation_deg_median"], 3),
                   rotation_deg_max=round(e["rotation_deg_max"], 3), n_over_5deg=int((rd > 5).sum()))
    else:
        from research.bench.bench_mapping import model_record
        rec.update(model_record(models, len(names), truth, capture))
    shutil.rmtree(tmp)
    return rec


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1:])), flush=True)
