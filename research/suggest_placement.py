"""Do ``curate suggest``'s poses stand in the room? Issue 49's check where the truth is known.

In the synthetic rooms of :mod:`curate.simulate.synthetic` (livingroom, office, kitchen) a deficient capture
(:func:`research.suggest_eval.deficient_walk`: ``corner``, ``turn``, ``corridor``; plus ``loop``, a whole lap, and
``orbit``, an object capture: one ring of photos around the room's point of interest, :func:`orbit_capture`)
gets stand-ins for its SfM points (:func:`research.suggest_eval.sfm_points`), and the walls take one of three
finishes:

* ``textured``: every surface gives points;
* ``sparse``: the room's four walls give a tenth of their points (a plain wall with a few features);
* ``plain``: the four walls give none (a white wall: SfM sees nothing on it).

The occupancy is built from the points as the occupancy stage builds it, and ``curate suggest``'s computation
(:func:`curate.suggest.stage.suggest`, its defaults) places ``--add`` poses. Each suggestion is checked against the
room's exact geometry:

* ``inside``: its centre lies in a solid or outside the room's interior (behind a wall);
* ``near``: its centre is nearer to a true surface (rays cast in 400 directions) than the clearance the capture
  itself kept from true surfaces (the same percentile and caps as :func:`curate.suggest.candidates.capture_envelope`
  applies to the estimated occupancy), less half a voxel;
* ``near_stated``: nearer to a true surface than the clearance curate states (``suggestions.json``'s envelope,
  measured on the estimated occupancy), less half a voxel.

Prints one JSON line per cell and a summary line last (the counts must be 0).

Usage:
  python -m research.suggest_placement --out /tmp/suggest_placement.jsonl
  python -m research.suggest_placement --rooms livingroom --walks corner --finishes plain --add 8
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOMS = ("livingroom", "office", "kitchen")
WALKS = ("corner", "turn", "corridor", "loop", "orbit")
FINISHES = ("textured", "sparse", "plain")


def fibonacci_dirs(n: int = 400) -> np.ndarray:
    """[n, 3] unit directions spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r = np.sqrt(1 - z * z)
    a = np.pi * (1 + 5 ** 0.5) * i
    return np.stack([r * np.cos(a), r * np.sin(a), z], 1)


def true_distance(world, centres: np.ndarray, n_dirs: int = 400) -> np.ndarray:
    """[n] distance from each centre to the nearest true surface (0 inside a solid or behind a wall)."""
    d = fibonacci_dirs(n_dirs)
    out = np.zeros(len(centres))
    inside = world.occupied(centres)
    for k, c in enumerate(np.asarray(centres, float)):
        if inside[k]:
            continue
        t = world.cast(np.repeat(c[None], len(d), 0), d)["t_hit"]
        out[k] = float(np.min(t))
    return out


def finish_points(world, pts: np.ndarray, finish: str, seed: int = 0) -> np.ndarray:
    """The points of a capture whose four walls have the finish ``finish`` (module docstring)."""
    if finish == "textured":
        return pts
    lo, hi = (np.asarray(a, float) for a in world.interior)
    tol = 0.05
    on_wall = ((pts[:, 0] < lo[0] + tol) | (pts[:, 0] > hi[0] - tol) |
               (pts[:, 1] < lo[1] + tol) | (pts[:, 1] > hi[1] - tol))
    keep = ~on_wall
    if finish == "sparse":
        keep |= on_wall & (np.random.default_rng(seed).random(len(pts)) < 0.1)
    return pts[keep]


def orbit_capture(world, seed: int, n: int = 48, radius: float = 1.3, rise: float = 0.6):
    """[<= n] cameras on one ring around ``world.poi`` (``radius`` from it, ``rise`` above it, a hand's jitter of
    5 cm), looking at it: an object capture filmed at one height. Centres inside furniture are left out."""
    from curate.core.cameras import Cameras, look_at
    from research import suggest_eval as se
    rng = np.random.default_rng(seed)
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = (world.poi + np.stack([radius * np.cos(a), radius * np.sin(a), np.full(n, rise)], 1)
         + rng.normal(0, 0.05, (n, 3)))
    c = c[~world.occupied(c)]
    w, h = se.SIZE
    f = 0.5 * w / np.tan(np.radians(60) / 2)
    return Cameras(look_at(c, np.broadcast_to(world.poi, c.shape)), f, f, w / 2, h / 2, w, h)


def capture(world, walk: str, seed: int):
    """The capture of ``walk`` in ``world`` (research.suggest_eval's deficient walks, or one whole lap)."""
    from research import suggest_eval as se
    if walk == "orbit":
        return orbit_capture(world, seed)
    if walk == "loop":
        from curate.simulate.walks import hand_held_walk
        cams, _ = hand_held_walk(se.lap_frames(world), "loop", seed=seed, width=se.SIZE[0], height=se.SIZE[1],
                                 fps=se.FPS, room=world.interior)
        return cams
    return se.deficient_walk(world, walk, seed)[0]


def run_inputs(cams, pts):
    """The suggest stage's inputs for a capture and its points, the occupancy built as the occupancy stage builds
    it from points."""
    from curate.occupancy.masks import OccupancyConfig, occupancy_from_points
    from curate.suggest.stage import RunInputs, surface_band
    grid = occupancy_from_points(pts, cams, OccupancyConfig())
    occ = np.asarray(grid.mask, bool)
    return RunInputs(cams, [""] * len(cams), [f"frame {i}" for i in range(len(cams))], "m", occ,
                     surface_band(occ, 1), np.asarray(grid.box_min, float), np.asarray(grid.box_max, float), [], [])


def truth_clearance(world, cams, env, look_depth: float, vox: float, pct: float) -> float:
    """The clearance the capture kept from true surfaces, with the envelope's caps."""
    from curate.suggest.candidates import MAX_CLEARANCE_SHARE
    d = true_distance(world, cams.centres)
    return max(min(float(np.percentile(d, pct)), MAX_CLEARANCE_SHARE * look_depth), vox)


def cell(room: str, walk: str, finish: str, add: int, seed: int) -> dict:
    from curate.simulate.synthetic import make_scene
    from curate.suggest.config import SuggestConfig
    from curate.suggest.freespace import voxel_size
    from curate.suggest.stage import suggest
    from research import suggest_eval as se
    world = make_scene(room, seed=0)
    cams = capture(world, walk, seed)
    depths = [world.depth(cams[k])[0] for k in range(len(cams))]
    pts = finish_points(world, se.sfm_points(cams, depths, seed=seed), finish, seed)
    inp = run_inputs(cams, pts)
    cfg = SuggestConfig(add=add, seed=seed)
    t0 = time.perf_counter()
    row = {"room": room, "walk": walk, "finish": finish, "n_capture": len(cams), "n_points": len(pts)}
    try:
        pl, feas, fs, *_ = suggest(cfg, inp)
    except ValueError as e:
        return {**row, "placed": 0, "inside": 0, "near": 0, "near_stated": 0, "error": str(e)}
    s = pl.cams
    vox = float(voxel_size(inp.box_min, inp.box_max, inp.res).max())
    need = truth_clearance(world, cams, feas.env, feas.env.look_depth, vox, cfg.clearance_percentile)
    dist = true_distance(world, s.centres)
    inside = world.occupied(s.centres)
    near = (~inside) & (dist < need - 0.5 * vox)
    stated = (~inside) & (dist < feas.env.clearance - 0.5 * vox)
    extra = {}
    if feas.kind == "object":       # an object capture: how many suggestions film above / below the ring
        o = feas.orbit
        v = s.centres - o.centre
        el = np.arcsin(np.clip(v @ feas.env.up / np.linalg.norm(v, axis=1), -1, 1))
        extra = {"kind": "object", "above_ring": int((el > o.captured[1]).sum()),
                 "below_ring": int((el < o.captured[0]).sum())}
    return {**row, "placed": len(s), "inside": int(inside.sum()), "near": int(near.sum()),
            "near_stated": int(stated.sum()),
            "min_distance": float(dist.min()) if len(s) else None, "truth_clearance": need,
            "clearance": feas.env.clearance, "feasible_voxels": int(len(feas.cells)),
            "seconds": time.perf_counter() - t0, **extra}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rooms", nargs="+", default=list(ROOMS), choices=ROOMS)
    ap.add_argument("--walks", nargs="+", default=list(WALKS), choices=WALKS)
    ap.add_argument("--finishes", nargs="+", default=list(FINISHES), choices=FINISHES)
    ap.add_argument("--add", type=int, default=8)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0])
    ap.add_argument("--out", type=Path, default=None, help="also append the JSON lines here")
    a = ap.parse_args(argv)
    rows = []
    for room in a.rooms:
        for walk in a.walks:
            for finish in a.finishes:
                for seed in a.seeds:
                    r = cell(room, walk, finish, a.add, seed)
                    rows.append(r)
                    line = json.dumps(r)
                    print(line, flush=True)
                    if a.out:
                        with open(a.out, "a") as f:
                            f.write(line + "\n")
    tot = {"cells": len(rows), "placed": sum(r["placed"] for r in rows), "inside": sum(r["inside"] for r in rows),
           "near": sum(r["near"] for r in rows), "near_stated": sum(r["near_stated"] for r in rows),
           "no_placement": sum(1 for r in rows if r["placed"] == 0)}
    print(json.dumps({"summary": tot}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
