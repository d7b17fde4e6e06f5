"""``curate suggest`` on real captures: does each suggestion stand in the room, and does each capture get an answer?

For every run folder given, ``curate suggest``'s computation (:func:`curate.suggest.stage.suggest`, defaults,
``--add`` poses, no field) runs on the run's own occupancy, and the row says how many poses it placed, the
capture's kind (walk or object), or the one line it says when nothing is feasible.

With ``--depth DIR`` (ground-truth depth maps, uint16 PNG in millimetres, one per camera of the run in
``cameras.json`` order, the run in the depth's metric frame: the office walk of ``../shared/data`` with its poses)
each suggestion's centre is checked against the truth: projected into every frame that sees it, it lies *in
front of* the surface there (its depth below the frame's true depth at that pixel) or *behind* it (more than
``--tolerance`` beyond). A centre in free space can be hidden from some frames (behind the sofa, seen from the
other side of the room) but stands in front of the surface in the frames that look at it from its side; a centre
inside a wall or behind it is behind the surface in every frame that has it in view. ``behind`` counts the
suggestions behind a true surface in at least 3 frames and in front of it in none; ``unseen`` those no frame with a
valid true depth has in view; ``margin`` is each centre's least distance in front of a seen surface.

Usage:
  python -m research.suggest_real /tmp/w/runs/office --depth ../shared/data/office/depth
  python -m research.suggest_real /tmp/w/runs/{office_mp4,drone,fox,skull,templering}
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np


def depth_check(cams, depth_dir: Path, centres: np.ndarray, tolerance: float) -> dict:
    """Per centre: frames that see it in front of / behind the true surface, and its least margin."""
    from PIL import Image
    files = sorted(depth_dir.glob("*.png"))
    if len(files) != len(cams):
        raise ValueError(f"{depth_dir}: {len(files)} depth maps for {len(cams)} cameras")
    front = np.zeros(len(centres), int)
    behind = np.zeros(len(centres), int)
    margin = np.full(len(centres), np.inf)
    for k, f in enumerate(files):
        d = np.asarray(Image.open(f), np.float64) / 1000.0
        uv, z = cams[k].project(centres)                    # [1, S, 2], [1, S]
        uv, z = uv[0], z[0]
        h, w = d.shape
        sx, sy = w / float(cams.width[k]), h / float(cams.height[k])
        u, v = np.floor(uv[:, 0] * sx).astype(int), np.floor(uv[:, 1] * sy).astype(int)
        ok = (z > 0) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        dd = np.where(ok, d[np.clip(v, 0, h - 1), np.clip(u, 0, w - 1)], 0.0)
        ok &= dd > 0
        front += ok & (z < dd + tolerance)
        behind += ok & (z > dd + tolerance)
        margin = np.where(ok & (z < dd), np.minimum(margin, dd - z), margin)
    return {"front": front.tolist(), "behind_frames": behind.tolist(),
            "margin": [float(m) if np.isfinite(m) else None for m in margin]}


def row(run: Path, add: int, depth: Path | None, tolerance: float) -> dict:
    from curate.suggest.config import SuggestConfig
    from curate.suggest.stage import read_run, suggest
    t0 = time.perf_counter()
    inp = read_run(run)
    out = {"run": str(run), "n_capture": len(inp.cams), "usable": inp.occupancy_usable()}
    try:
        pl, feas, *_ = suggest(SuggestConfig(add=add, field="none"), inp)
    except ValueError as e:
        return {**out, "placed": 0, "said": str(e), "seconds": time.perf_counter() - t0}
    s = pl.cams
    out.update({"placed": len(s), "kind": feas.kind,
                "clearance": feas.env.clearance, "seconds": time.perf_counter() - t0})
    if depth is not None:
        chk = depth_check(inp.cams, depth, s.centres, tolerance)
        out.update(chk)
        out["behind"] = int(sum(b >= 3 and f == 0 for f, b in zip(chk["front"], chk["behind_frames"])))
        out["unseen"] = int(sum(f == 0 and b == 0 for f, b in zip(chk["front"], chk["behind_frames"])))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--add", type=int, default=8)
    ap.add_argument("--depth", type=Path, default=None, help="ground-truth depth maps (one run only)")
    ap.add_argument("--tolerance", type=float, default=0.1, help="metres beyond the true depth that count as behind")
    a = ap.parse_args(argv)
    for r in a.runs:
        print(json.dumps(row(r, a.add, a.depth, a.tolerance)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
