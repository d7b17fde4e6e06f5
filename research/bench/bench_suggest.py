"""Benchmark of ``curate suggest``'s placement: milliseconds per scored candidate and per placed camera.

Cases:
  room   a hand-held loop of 300 frames through the synthetic living room
         (:func:`curate.simulate.walks.hand_held_walk`, 320x240), the room's exact occupancy on a 32^3 grid over its
         box, its surface band as nodes: every step of the stage after reading the run folder (free-space cast,
         envelope, feasibility, the capture's energy state, K placed cameras with each ``--candidates``).
  run    the same steps on a run folder (``--run RUN``, e.g. ``curate run office.mp4 --no-evaluate``), with its
         ``occupancy.npz`` and every registered camera.

Per placed camera: ``draw`` (feasible candidates drawn and tested), ``score`` (their visibility pairs and
``E(capture + placed + {c})`` for each, :meth:`curate.select.greedy.NodeState.scores_of`). Medians over the K
steps; the first step includes numba's / torch's one-time warm-up only in ``setup``. The machine's load average is
printed with the figures (a shared machine's timings move with it).

Prints one JSON object as its last line.
Usage: nice -n 10 python3 -m research.bench.bench_suggest [--run /tmp/office_run] [--add 8] [--candidates 250,1000,4000]
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import numpy as np


def _case_room():
    from curate.core.grid import NodeGrid
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk
    from curate.suggest.stage import surface_band
    s = make_scene("livingroom", 0)
    lo, hi = s.interior
    g = NodeGrid(lo - 0.1, hi + 0.1, 32)
    occ = s.occupied(g.all_nodes()).reshape((32,) * 3)
    walk, _ = hand_held_walk(300, "loop", seed=1, width=320, height=240, room=s.interior)
    return walk, occ, surface_band(occ, 1), g.box_min, g.box_max


def _case_run(run):
    from curate.suggest.stage import read_run
    inp = read_run(run)
    if not inp.occupancy_usable():
        raise SystemExit(f"{run}: its occupancy cannot place cameras (run `curate suggest` once: it trains a field)")
    return inp.cams, inp.occ, inp.nodes_mask, inp.box_min, inp.box_max


def bench(cams, occ, nodes_mask, lo, hi, add: int, n_cands: list[int]) -> dict:
    from curate.core.grid import NodeGrid
    from curate.suggest.candidates import Feasibility, capture_envelope
    from curate.suggest.freespace import cast_free_space
    from curate.suggest.place import place_cameras
    t = time.perf_counter()
    fs = cast_free_space(cams, occ, lo, hi)
    cast_s = time.perf_counter() - t
    t = time.perf_counter()
    env = capture_envelope(cams, fs, occ, lo, hi)
    feas = Feasibility(occ, lo, hi, fs.free, env)
    feas_s = time.perf_counter() - t
    nodes = NodeGrid(lo, hi, occ.shape[0], nodes_mask).nodes()
    place_cameras(cams, nodes, feas, 1, 50)                      # warm-up: numba kernel, torch
    out = {"n_capture": len(cams), "n_nodes": len(nodes), "res": int(occ.shape[0]),
           "cast_free_space_s": round(cast_s, 3), "envelope_feasibility_s": round(feas_s, 3),
           "feasible_voxels": int(len(feas.cells)), "per_candidates": {}}
    for n in n_cands:
        pl = place_cameras(cams, nodes, feas, add, n)
        tm = pl.timing()
        k = np.asarray(pl.n_candidates, float)
        out["per_candidates"][str(n)] = {
            "placed": len(pl.cams), "ms_per_camera": round(tm["ms_per_camera"], 1),
            "ms_per_candidate": round(tm["ms_per_candidate"], 4),
            "draw_ms_per_candidate": round(float(np.median(np.asarray(pl.draw_seconds) / k)) * 1e3, 4),
            "score_ms_per_candidate": round(tm["ms_per_candidate_scoring"], 4),
            "setup_s": round(pl.setup_seconds, 3), "energy_gain": round(pl.energy[-1] - pl.energy_before, 2)}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", default="", help="also a run folder (case 'run')")
    ap.add_argument("--add", type=int, default=8)
    ap.add_argument("--candidates", default="250,1000,4000")
    args = ap.parse_args(argv)
    n_cands = [int(x) for x in args.candidates.split(",") if x]
    res = {"load_before": os.getloadavg()[0], "cores": os.cpu_count()}
    res["room"] = bench(*_case_room(), args.add, n_cands)
    if args.run:
        res["run"] = {"path": args.run, **bench(*_case_run(args.run), args.add, n_cands)}
    res["load_after"] = os.getloadavg()[0]
    for case in ("room", "run"):
        if case in res:
            for n, v in res[case]["per_candidates"].items():
                print(f"{case:5s} {n:>5s} candidates: {v['ms_per_camera']:8.1f} ms per placed camera, "
                      f"{v['ms_per_candidate']:.3f} ms per candidate (draw {v['draw_ms_per_candidate']:.3f}, "
                      f"score {v['score_ms_per_candidate']:.3f})")
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    sys.exit(main())
