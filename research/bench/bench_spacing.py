"""Time of ``--budget auto``'s spacing curve against the selection it precedes (view medoids of 15%).

Prints one JSON line per pool size: seconds of :func:`curate.select.spacing.spacing_curve` (the
whole curve, k = 1..K), of :func:`curate.select.auto_budget.choose_budget`, and of
:func:`curate.select.medoids.medoids_select` at 15% of the pool, on a synthetic walk of K views
(a loop with jitter), and their ratio (the same run, so comparable on a noisy machine)::

    python3 -m research.bench.bench_spacing --sizes 300 1000 3000
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def walk_cameras(n: int, seed: int = 0):
    from curate.core.cameras import Cameras, look_at
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([2 * np.cos(t), 2 * np.sin(t), np.zeros(n)], 1) + rng.normal(0, 0.02, (n, 3))
    target = c + np.stack([np.cos(t + 0.6), np.sin(t + 0.6), rng.normal(0, 0.1, n)], 1)
    f = np.full(n, 200.0)
    return Cameras(look_at(c, target), f, f, np.full(n, 160.0), np.full(n, 120.0), np.full(n, 320), np.full(n, 240),
                   names=tuple(f"f_{i:05d}.jpg" for i in range(n)))


def main(argv=None) -> int:
    from curate.select.auto_budget import choose_budget
    from curate.select.config import MedoidsConfig
    from curate.select.medoids import embed, medoids_select
    from curate.select.spacing import spacing_curve
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[300, 1000, 3000])
    args = ap.parse_args(argv)
    for n in args.sizes:
        cams = walk_cameras(n)
        depths = np.full(n, 3.0)
        c, a = embed(cams, depths)
        t0 = time.perf_counter()
        spacing_curve(c, a, depths)
        t_curve = time.perf_counter() - t0
        t0 = time.perf_counter()
        ch = choose_budget(c, a, depths)
        t_choose = time.perf_counter() - t0
        t0 = time.perf_counter()
        medoids_select(cams, max(2, round(0.15 * n)), MedoidsConfig(depth=3.0, path_weights=False))
        t_med = time.perf_counter() - t0
        print(json.dumps({"views": n, "curve_s": round(t_curve, 4), "choose_s": round(t_choose, 4),
                          "medoids_15pct_s": round(t_med, 4), "curve_over_medoids": round(t_curve / t_med, 3),
                          "chosen": ch.budget}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
