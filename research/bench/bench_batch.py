"""Wall time of one folder's evaluation trainings: serially in this process vs as Ray tasks.

    nice -n 5 python3 -m research.bench.bench_batch --iters 100 --out /tmp/bench_batch

Prepares a run folder of the sample pool up to the selection (SfM import, occupancy with
the pool field, selection), then runs the evaluation's trainings (selection, random
seeds, FVS; 'all' reuses the pool field) twice from scratch: serially (one worker) and
through :class:`curate.core.executors.RayExecutor` on a local Ray instance (``--ray-cpus``,
default the machine's cores), optionally also with the local process pool. Last line:
JSON with the seconds, the ratio and whether the PSNRs agree.
"""

from __future__ import annotations

import argparse
import json
import shutil
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    from curate import pipeline as pl
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.evaluate.units import EvalConfig
    from curate.core.executors import RayExecutor, cpu_count, ray_init
    from curate.occupancy.masks import OccupancyConfig

    ap = argparse.ArgumentParser()
    ap.add_argument("--iters", type=int, default=200)
    ap.add_argument("--eval-size", type=int, default=240)
    ap.add_argument("--random-seeds", type=int, default=3)
    ap.add_argument("--budget", default="15%")
    ap.add_argument("--ray-cpus", type=int, default=0)
    ap.add_argument("--pool", action="store_true", help="also time the local process pool (one worker per core)")
    ap.add_argument("--out", default="/tmp/bench_batch")
    a = ap.parse_args()
    sample = ROOT / "data_samples" / "room_walk"
    run_dir = Path(a.out)
    cfg = pl.RunConfig(budget=a.budget, occupancy=OccupancyConfig(res=24),
                       evaluate=EvalConfig(iters=a.iters, max_side=a.eval_size, random_seeds=a.random_seeds, workers=1))
    t0 = time.perf_counter()
    pl.run(replace(cfg, run_evaluation=False), sample, run_dir, poses=sample / "transforms.json")
    prep = time.perf_counter() - t0

    def evaluate(executor=None, workers=1):
        shutil.rmtree(run_dir / "evaluate", ignore_errors=True)
        c = replace(cfg, evaluate=replace(cfg.evaluate, workers=workers))
        t = time.perf_counter()
        run_stage(BY_NAME["evaluate"], RunContext(c, run_dir, executor=executor))
        dt = time.perf_counter() - t
        s = json.loads((run_dir / "evaluate" / "summary.json").read_text())["methods"]
        units = {p.parent.name: json.loads(p.read_text())["train_seconds"]
                 for p in (run_dir / "evaluate").glob("*/metrics.json")}
        return dt, {m: round(v["psnr"], 4) for m, v in s.items()}, units

    res = {"iters": a.iters, "eval_size": a.eval_size, "cores": cpu_count(), "prep_seconds": round(prep, 1)}
    t_serial, p_serial, u_serial = evaluate(None, 1)
    res.update(serial_seconds=round(t_serial, 1), serial_unit_train_seconds=u_serial, psnr=p_serial)
    if a.pool:
        t_pool, p_pool, _ = evaluate(None, 0)
        res.update(pool_seconds=round(t_pool, 1), pool_psnr_equal=p_pool == p_serial)
    t = time.perf_counter()
    ray = ray_init(None, a.ray_cpus or None)
    res["ray_init_seconds"] = round(time.perf_counter() - t, 1)
    t_ray, p_ray, u_ray = evaluate(RayExecutor(num_cpus=1), 1)
    ray.shutdown()
    res.update(ray_seconds=round(t_ray, 1), ray_unit_train_seconds=u_ray, ray_psnr_equal=p_ray == p_serial,
               ray_psnr=p_ray, ratio_serial_over_ray=round(t_serial / t_ray, 2))
    print(json.dumps(res))


if __name__ == "__main__":
    main()
