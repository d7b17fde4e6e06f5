"""The incremental mapper on a finished run's matches with COLMAP's schedule of global adjustments (or
OPTION=VALUE overrides of pycolmap.IncrementalPipelineOptions): CPU and wall seconds, model sizes and
pose error, one JSON line (docs/sfm.md, "Mapping past 1,000 photos").

    python3 -m research.ba_schedule RUN TRUTH KIND [ba_global_frames_ratio=1.5 ba_global_points_ratio=1.5 ...]

KIND: ``video`` (TRUTH a ground-truth folder such as ../shared/data/office, RUN from its video) or
``walk`` (TRUTH a folder rendered by research.bench.bench_mapping, with truth.npy).
"""
import json, shutil, sys, tempfile, time, resource
from pathlib import Path
import numpy as np, pycolmap
from curate.sfm.config import SfmConfig
import curate.sfm.colmap as C
run, truth, capture = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
ov = dict(a.split("=") for a in sys.argv[4:])
sfm = run / "sfm"
cfg = SfmConfig(progress=False)
tmp = Path(tempfile.mkdtemp()); db = tmp / "d.db"; shutil.copy2(sfm / "database.db", db)
names = sorted(p.name for p in (sfm / "images").iterdir())
orig = C.incremental_options
def patched(cfg, n_images=0):
    try:
        o = orig(cfg, 0)   # COLMAP's schedule, then the overrides
    except TypeError:
        o = orig(cfg)
    for k, v in ov.items():
        setattr(o, k, type(getattr(o, k))(float(v)) if not isinstance(getattr(o, k), bool) else v == "1")
    return o
C.incremental_options = patched
pycolmap.set_random_seed(0)
r0 = resource.getrusage(resource.RUSAGE_SELF); t0 = time.perf_counter()
with C.colmap_log(tmp / "colmap.log"):
    models = C._map(cfg, db, sfm / "images", tmp / "m", len(names), False)
r1 = resource.getrusage(resource.RUSAGE_SELF)
rec = {"run": str(run), "overrides": ov, "wall_s": round(time.perf_counter() - t0, 1),
       "cpu_s": round(r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime, 1)}
if capture == "video":
    from research.align import pose_errors
    from research.datasets import load_ground_truth
    from research.sfm_mappers import truth_for
    recs = json.loads((sfm / "images.json").read_text()).get("photos", [])
    frame_of = {r["working"]: r["extra"]["frame"] for r in recs if (r.get("extra") or {}).get("video")}
    best = max(models.values(), key=lambda r: r.num_reg_images())
    cams = C.cameras_from_reconstruction(best, warn=False)[0]
    e = pose_errors(*truth_for(cams, load_ground_truth(Path(truth)), frame_of))
    rd = np.asarray(e["rotation_deg"])
    rec.update(model_sizes=sorted((int(r.num_reg_images()) for r in models.values()), reverse=True),
               rotation_deg_median=round(e["rotation_deg_median"], 3), rotation_deg_max=round(e["rotation_deg_max"], 3),
               n_over_5deg=int((rd > 5).sum()))
else:
    from research.bench.bench_mapping import model_record
    rec.update(model_record(models, len(names), truth, capture))
print(json.dumps(rec), flush=True)
shutil.rmtree(tmp)
