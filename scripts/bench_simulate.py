"""The paper's synthetic comparison on the three procedural rooms, at a CPU-sized setting.

Defaults: budget 60 cameras per method, 160x120 images, 30 test views per test set,
300 random candidates per placement step (the paper: 1000), 24^3 node grid, 1000 field
training iterations per method and room (a fixed count, fair under a varying load), occupancy from the scene (oracle variant). Every setting is
a flag and the settings used are printed in the JSON.

Prints one JSON object as its last line: ``table`` maps train method (ours, random,
hemisphere, fvs) -> test set (random, hemisphere, ours, average) -> mean PSNR over the
rooms, ``per_scene`` the same per room, plus ``seeds`` and timings.

Usage: python scripts/bench_simulate.py [--budget 60] [--train-seconds 60] [--scenes livingroom,office,kitchen]
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from dataclasses import asdict

import numpy as np

from curate.energy import EnergyConfig
from curate.progressive import CameraSpec, ProgressiveConfig
from curate.simulate import METHODS, TEST_SETS, SimulateConfig, run_simulation


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
    a = ap.parse_args()
    w, h = (int(v) for v in a.size.split("x"))
    out = a.out or tempfile.mkdtemp(prefix="bench_simulate_")
    per_scene, timings = {}, {}
    for scene in a.scenes.split(","):
        cfg = SimulateConfig(scene=scene, budget=a.budget, n_test=a.n_test, node_res=a.res,
                             train_seconds=a.train_seconds, train_iters=a.train_iters or None, seed=a.seed,
                             placement=ProgressiveConfig(n_candidates=a.candidates, energy=EnergyConfig(),
                                                         camera=CameraSpec(w, h)))
        rep = run_simulation(cfg, f"{out}/{scene}")
        per_scene[scene] = rep["table"]
        timings[scene] = {**rep["timings"], "propose_seconds_per_camera": rep["propose_seconds_per_camera"],
                          "wall_seconds": rep["wall_seconds"]}
        print(f"{scene}: {json.dumps(rep['table'])}", file=sys.stderr)
    cols = list(TEST_SETS) + ["average"]
    table = {m: {t: float(np.mean([per_scene[s][m][t] for s in per_scene])) for t in cols} for m in METHODS}
    ours_wins = {t: all(table["ours"][t] > table[b][t] for b in ("random", "hemisphere")) for t in ("random", "ours")}
    print(json.dumps({"table": table, "per_scene": per_scene, "seeds": {"placement_and_training": a.seed,
                      "test_sets": [a.seed + 1000 + i for i in range(3)], "scene_seed": 0},
                      "ours_beats_random_and_hemisphere": ours_wins,
                      "settings": {**vars(a), "size": [w, h], "occupancy": "oracle (scene geometry)",
                                   "energy": asdict(EnergyConfig())},
                      "timings": timings, "out": out}))


if __name__ == "__main__":
    main()
