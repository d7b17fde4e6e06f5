"""The paper's synthetic comparison on the three procedural rooms, at a CPU-sized setting.

Defaults: budget 60 cameras per method, 160x120 images, 30 test views per test set,
300 random candidates per placement step (the paper: 1000), 24^3 node grid, 1000 field
training iterations per method and room (a fixed count, fair under a varying load), occupancy from the scene
(oracle variant). Every setting is a flag and the settings used are printed in the JSON.

Prints one JSON object as its last line: ``table`` maps train method (ours, random,
hemisphere, fvs) -> test set (random, hemisphere, ours, average) -> mean PSNR over the
rooms, ``per_scene`` the same per room, plus ``seeds`` and timings.

Usage: python3 -m research.bench.bench_simulate [--budget 60] [--train-seconds 60] [--scenes livingroom,office,kitchen]

``--occupancy field`` runs ours with occupancy from the field trained as cameras are added
(``--train-between`` iterations after each, the paper's Algorithm 1); ``--occupancy both``
runs the field variant (ours only) next to the oracle run and reports rows ``ours (field)``
and ``ours (oracle)`` (same seeds, hence the same test sets), plus the field loop's time
per proposed camera (placement, training between additions, occupancy update).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import asdict

import numpy as np

from curate.select.config import EnergyConfig
from curate.field.model import FieldConfig
from curate.simulate.progressive import CameraSpec, FieldOccupancyConfig, ProgressiveConfig
from curate.simulate.experiment import METHODS, TEST_SETS, SimulateConfig, run_simulation


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", default="livingroom,office,kitchen")
    ap.add_argument("--budget", type=int, default=60)
    ap.add_argument("--n-test", type=int, default=30)
    ap.add_argument("--candidates", type=int, default=300)
    ap.add_argument("--res", type=int, default=24)
    ap.add_argument("--train-seconds", type=float, default=60.0)
    ap.add_argument("--train-iters", type=int, default=1000,
                    help="fixed iterations per training (fair under a varying machine load); 0 uses --train-seconds")
    ap.add_argument("--size", default="160x120")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="keep the run folders here (default: a temporary folder)")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--occupancy", default="oracle", choices=["oracle", "field", "both"])
    ap.add_argument("--train-between", type=int, default=250, help="field variant: iterations after each camera")
    ap.add_argument("--n-free-first", type=int, default=20, help="cameras drawn in the free box first")
    ap.add_argument("--min-iters", type=int, default=1000,
                    help="field variant: iterations before its occupancy is used")
    ap.add_argument("--loop-rays", type=int, default=0, help="field variant: rays per iteration of the loop's field "
                    "(0: the default field's)")
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    out = a.out or tempfile.mkdtemp(prefix="bench_simulate_")
    methods = tuple(a.methods.split(","))
    loop_field = FieldConfig(val_every=0, batch_rays=a.loop_rays,
                             occ_update_start=max(1, min(100, a.train_between // 2)),
                             occ_update_every=max(1, min(100, a.train_between // 2))) if a.loop_rays else None
    runs = {"oracle": [("oracle", methods)], "field": [("field", methods)],
            "both": [("oracle", methods), ("field", ("ours",))]}[a.occupancy]
    per_scene, timings, field_loops = {}, {}, {}
    for scene in a.scenes.split(","):
        per_scene[scene] = {}
        for occ, meths in runs:
            cfg = SimulateConfig(scene=scene, budget=a.budget, n_test=a.n_test, node_res=a.res, methods=meths,
                                 train_seconds=a.train_seconds, train_iters=a.train_iters or None, seed=a.seed,
                                 occupancy=occ, train_between=a.train_between, loop_field=loop_field,
                                 field_occupancy=FieldOccupancyConfig(min_iters=a.min_iters),
                                 placement=ProgressiveConfig(n_candidates=a.candidates, energy=EnergyConfig(),
                                                             camera=CameraSpec(w, h), n_free_first=a.n_free_first))
            rep = run_simulation(cfg, f"{out}/{scene}" + ("_field" if a.occupancy == "both" and occ == "field" else ""))
            for m, row in rep["table"].items():
                per_scene[scene][f"{m} ({occ})" if a.occupancy == "both" and m == "ours" else m] = row
            key = scene if a.occupancy != "both" else f"{scene} ({occ})"
            timings[key] = {**rep["timings"], "propose_seconds_per_camera": rep["propose_seconds_per_camera"],
                            "wall_seconds": rep["wall_seconds"]}
            if rep.get("field_loop"):
                field_loops[scene] = {k: v for k, v in rep["field_loop"].items() if k != "per_camera"}
        print(f"{scene}: {json.dumps(per_scene[scene])}", file=sys.stderr)
    cols = list(TEST_SETS) + ["average"]
    rows = list(next(iter(per_scene.values())))
    table = {m: {t: float(np.mean([per_scene[s][m][t] for s in per_scene])) for t in cols} for m in rows}
    ours_rows = [m for m in rows if m.startswith("ours")]
    ours_wins = {o: {t: all(table[o][t] > table[b][t] for b in ("random", "hemisphere") if b in table)
                     for t in ("random", "ours")} for o in ours_rows}
    print(json.dumps({"table": table, "per_scene": per_scene, "seeds": {"placement_and_training": a.seed,
                      "test_sets": [a.seed + 1000 + i for i in range(3)], "scene_seed": 0},
                      "ours_beats_random_and_hemisphere": ours_wins,
                      "settings": {**vars(a), "size": [w, h], "energy": asdict(EnergyConfig()),
                                   "occupancy_note": "ours: " + {"oracle": "scene geometry",
                                                                 "field": "the field trained as cameras are added",
                                                                 "both": "both variants"}[a.occupancy]
                                   + "; baselines and test sets: scene geometry"},
                      "field_loop": field_loops, "timings": timings, "out": out}))


if __name__ == "__main__":
    main()
