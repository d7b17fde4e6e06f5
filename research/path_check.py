"""Each video take (and take of numbered photos) of a finished SfM run along its path: the islands
`curate.sfm.continuity.off_path` finds (for numbered photos only reported: curate leaves none out),
the largest steps between consecutive frames as multiples of the take's median speed, and the
largest as multiples of the speed around them (`step_ratios`: what `path_jumps` reports a fold by).

Reads ``RUN/sfm/images.json`` and every model under ``RUN/sfm/sparse/`` (the frames the run already
left out are not in them: run it on a run made before the check to see what it finds). One JSON line
per model and take.

    python3 -m research.path_check /tmp/takes_runs/three /tmp/office_run
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def kept_records(run: Path) -> list:
    """The kept PhotoRecords of a run's SfM stage, as ``curate sfm`` held them (``RUN/sfm/images.json``)."""
    from curate.core.images import PhotoRecord
    kept = []
    for r in json.loads((run / "sfm" / "images.json").read_text())["photos"]:
        if r.get("status") == "kept":
            pr = PhotoRecord(original=r.get("original", r["rel"]), rel=r["rel"], working=r["working"])
            pr.extra.update(r.get("extra") or {})
            kept.append(pr)
    return kept


def takes_along(run: Path):
    """Yield (model folder name, take, [n] times, [n] names, [n, 3] centres) per model and take: video
    takes, and takes of numbered photos in name order (their numbers as the time), as
    ``curate.sfm.continuity.jumps_along`` reads them."""
    import pycolmap

    from curate.sfm.continuity import frame_times, times_and_centres, video_takes
    when = frame_times(kept_records(run), numbered=True)
    for model in sorted((run / "sfm" / "sparse").iterdir()):
        for take, frames in video_takes(pycolmap.Reconstruction(model), when).items():
            t, c = times_and_centres(frames)
            yield model.name, take, t, [im.name for _, im in frames], c


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", type=Path, nargs="+", help="run folders whose SfM stage finished")
    a = ap.parse_args(argv)
    from curate.sfm.continuity import speeds, off_path, path_jumps, step_ratios
    for run in a.runs:
        for model, take, t, names, c in takes_along(run):
            isl = off_path(t, c)
            v = speeds(t, c)
            med = float(np.median(v)) if len(v) else 0.0
            ratio = v / med if med > 0 else np.zeros_like(v)
            around = step_ratios(t, c)
            steps = np.ones(len(v), bool)           # the steps into, inside and out of an island
            for i in isl:
                steps[max(i - 1, 0):i + 1] = False
            print(json.dumps({"run": str(run), "model": model, "take": take, "frames": len(t),
                              "islands": [names[i] for i in isl],
                              "largest_steps_x_median": np.sort(ratio)[-4:].round(2).tolist(),
                              "largest_step_elsewhere_x_median": round(float(ratio[steps].max()), 2)
                              if steps.any() else None,
                              "largest_steps_x_around": np.sort(around)[-4:].round(2).tolist(),
                              "largest_step_elsewhere_x_around": round(float(around[steps].max()), 2)
                              if steps.any() else None,
                              "jumps": [(names[i - 1], names[i], round(r, 2)) for i, r in path_jumps(t, c)]}),
                  flush=True)


if __name__ == "__main__":
    main()
