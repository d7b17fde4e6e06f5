"""Where a model of a rendered capture is folded: the turn of each photo relative to its neighbour in name
order, model against truth (no alignment needed, so a fold shows as one step, not as every photo off).

    python3 -m research.fold_check RUN FRAMES KIND     # KIND and FRAMES as research.bench.bench_mapping renders

Prints one JSON line: the photos compared, the median and largest disagreement between consecutive
photos' relative rotations (model against truth), every step where it is over ``--over`` degrees, and
every 100th photo's disagreement from the first photo (where a bend spreads over many steps).
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from curate.core.cameras import rotation_angle_deg


def relative_turns(model_c2w: np.ndarray, truth_c2w: np.ndarray) -> np.ndarray:
    """[n - 1] degrees: for each pair of consecutive photos, the angle between the model's rotation from
    one to the next and the truth's. model_c2w, truth_c2w: [n, 4, 4] (or [n, 3, 3]) camera-to-world, in
    the same photo order."""
    Rm, Rt = np.asarray(model_c2w)[:, :3, :3], np.asarray(truth_c2w)[:, :3, :3]
    a = np.einsum("nji,njk->nik", Rm[:-1], Rm[1:])            # R_i^T R_{i+1}
    b = np.einsum("nji,njk->nik", Rt[:-1], Rt[1:])
    return rotation_angle_deg(np.einsum("nji,njk->nik", a, b))         # a^T b


def relative_turns_to(model_c2w: np.ndarray, truth_c2w: np.ndarray) -> np.ndarray:
    """[n] degrees: for each photo, the angle between the model's rotation from the first photo to it
    and the truth's (0 for the first): a bend shows as a value that grows along the photos."""
    Rm, Rt = np.asarray(model_c2w)[:, :3, :3], np.asarray(truth_c2w)[:, :3, :3]
    a = np.einsum("ji,njk->nik", Rm[0], Rm)
    b = np.einsum("ji,njk->nik", Rt[0], Rt)
    return rotation_angle_deg(np.einsum("nji,njk->nik", a, b))


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("frames", type=Path, help="the rendered capture's folder (truth.npy)")
    ap.add_argument("kind", help="walk, hall, hall_back or grid")
    ap.add_argument("--over", type=float, default=2.0, help="report steps disagreeing by more (deg)")
    a = ap.parse_args(argv)
    from curate.sfm.io import load_sfm
    from research.bench.bench_mapping import truth_cameras
    got, truth = load_sfm(a.run).cameras, truth_cameras(a.frames, a.kind)
    at = {n: i for i, n in enumerate(truth.names)}
    order = sorted(range(len(got.names)), key=lambda i: at[got.names[i]])
    names = [got.names[i] for i in order]
    d = relative_turns(got.c2w[order], truth.c2w[[at[n] for n in names]])
    from_first = [float(x) for x in relative_turns_to(got.c2w[order], truth.c2w[[at[n] for n in names]])]
    out = {"run": str(a.run), "photos": len(names), "median_deg": round(float(np.median(d)), 3),
           "from_first_every_100": [(names[k], round(from_first[k], 1)) for k in range(0, len(names), 100)],
           "max_deg": round(float(d.max()), 2),
           "steps_over": [(names[k], names[k + 1], round(float(d[k]), 1)) for k in np.flatnonzero(d > a.over)]}
    print(json.dumps(out), flush=True)
    return out


if __name__ == "__main__":
    main()
