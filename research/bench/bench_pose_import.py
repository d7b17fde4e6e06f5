#!/usr/bin/env python
"""Known poses without points: the points triangulated for them, and what a 15% export keeps.

    python3 -m research.bench.bench_pose_import --data data_samples/room_walk ../shared/data/fox \\
        ../shared/data/office ../shared/data/templering --work /tmp/bench_pose_import

For each data set: its poses as a transforms.json (room_walk and fox: their own; the office and the
templering: the ground truth of ``research.datasets``, written to ``WORK/<name>/transforms.json``),
then, in a fresh process, ``curate run PHOTOS --poses TRANSFORMS --no-evaluate --budget 15% --out
WORK/<name>/run`` (``--extra`` adds flags). Reported per data set: the triangulation's statistics
(``RUN/sfm/stage.json``: seconds per step, points, mean track length, mean reprojection error at the
working size, verified pairs, images seeing a point), the export's model (``RUN/export/export.json``:
points, images that see them, ``components``), the wall and CPU time of the run and the machine's load
average before and after it (the machine may be shared: compare CPU seconds). One line per data set,
and as the LAST line one JSON object ``{name: result}``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def poses_of(folder: Path, work: Path) -> tuple[Path, Path]:
    """(photo folder, transforms.json) of a sample folder."""
    from curate.core.transforms_json import write_transforms
    from research.datasets import image_folder, load_office, load_templering
    if (folder / "transforms.json").is_file():
        return image_folder(folder), folder / "transforms.json"
    if (folder / "templeR_par.txt").is_file():
        cams, photos = load_templering(folder), folder
    elif (folder / "poses.txt").is_file():
        cams, photos = load_office(folder), folder / "images"
    else:
        raise ValueError(f"{folder}: no known poses")
    work.mkdir(parents=True, exist_ok=True)
    tj = work / "transforms.json"
    write_transforms(tj, cams, list(cams.names))   # names relative to the photo folder given beside it
    return photos, tj


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", nargs="+", required=True, help="sample folders with known poses")
    ap.add_argument("--work", default="/tmp/bench_pose_import", help="parent of the run folders")
    ap.add_argument("--budget", default="15%")
    ap.add_argument("--extra", nargs=argparse.REMAINDER, default=[], help="more flags for curate run")
    a = ap.parse_args(argv)
    results = {}
    for folder in map(Path, a.data):
        name = folder.resolve().name
        work = Path(a.work) / name
        photos, tj = poses_of(folder.resolve(), work)
        run = work / "run"
        cmd = [sys.executable, "-m", "curate", "run", str(photos), "--poses", str(tj), "--no-evaluate",
               "--budget", a.budget, "--out", str(run), *a.extra]
        t, cpu = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
        load = os.getloadavg()[0]
        p = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})
        end = resource.getrusage(resource.RUSAGE_CHILDREN)
        res: dict = {"command": " ".join(cmd), "wall_seconds": round(time.perf_counter() - t, 1),
                     "cpu_seconds": round(end.ru_utime + end.ru_stime - cpu.ru_utime - cpu.ru_stime, 1),
                     "load_before": round(load, 1), "load_after": round(os.getloadavg()[0], 1),
                     "returncode": p.returncode}
        if p.returncode != 0:
            res["error"] = p.stderr.strip().splitlines()[-1:] or p.stdout.strip().splitlines()[-1:]
        else:
            st = json.loads((run / "sfm" / "stage.json").read_text())["stats"]
            model = json.loads((run / "export" / "export.json").read_text())["model"]
            res.update(n_poses=st["n_poses"], n_registered=st["n_registered"], triangulation=st.get("triangulation"),
                       export={k: model.get(k) for k in ("n_images", "n_points3D", "n_points3D_source",
                                                         "n_images_with_points", "components")},
                       warnings=[ln for ln in p.stdout.splitlines() if ln.startswith("WARNING")])
            tri = st.get("triangulation") or {}
            print(f"{name}: {tri.get('n_points')} points in {tri.get('seconds')} s (track "
                  f"{tri.get('mean_track_length')}, {tri.get('mean_reprojection_error_px')} px); export "
                  f"{model['n_images']} images, {model['n_points3D']} points seen by "
                  f"{model.get('n_images_with_points')}, "
                  f"components {model['components']}", flush=True)
        results[name] = res
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
