"""The field's grid lookups on a real training's samples: ``grid_sample`` against the corners' ``index_add``.

For a run folder, the evaluation's field (``curate.evaluate.config.evaluation_field``) is trained on every
``--stride``-th registered photo at the evaluation's size for ``--iters`` iterations; then one batch of training rays
is sampled as ``RadianceField.render_rays`` samples it (the samples in active cells), and each grid (density: 1
channel, colour: 3) is read at those samples ``--repeats`` times both ways, forward and backward, one torch thread:
``grid_sample`` (what rendering uses) and :func:`curate.field.model.trilinear` on the samples'
:func:`curate.field.model.trilinear_corners` (what training uses since 2026-11-30). Prints one JSON line: samples,
milliseconds per call (median over the repeats) of each way and step, and the largest difference of values and of
gradients between the two.

    python -m research.bench.bench_lookup RUN [--iters 300] [--stride 6] [--repeats 20]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("--iters", type=int, default=300)
    ap.add_argument("--stride", type=int, default=6)
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)
    import torch
    import torch.nn.functional as F
    from curate.evaluate.config import EvalConfig
    from curate.evaluate.units import eval_cameras
    from curate.field.metrics import camera_rays
    from curate.field.model import trilinear, trilinear_corners
    from curate.field.train import default_box, train_field
    from curate.sfm.io import image_paths, load_sfm
    torch.set_num_threads(1)
    sfm = load_sfm(args.run)
    cams = sfm.cameras
    paths = image_paths(args.run, list(cams.names), sfm.records)
    ev = EvalConfig()
    sub = list(range(0, len(cams), args.stride))
    ec = eval_cameras(cams, ev.train_side())[sub]
    fld, _ = train_field(ev.field, ec, [paths[i] for i in sub], None, iters=args.iters, seed=0, box=default_box(cams))
    o, d = zip(*(camera_rays(ec, i) for i in range(len(ec))))
    o, d = torch.cat(o), torch.cat(d)
    pick = torch.randint(0, len(o), (ev.field.batch_rays,), generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        _, c, _ = fld.sample(o[pick], d[pick], jitter=torch.Generator().manual_seed(1))
        g = fld.to_unit(c).reshape(-1, 3)
        g = g[fld._occ_lookup_unit(g)]
    out = {"run": str(args.run), "iters": args.iters, "photos": len(sub), "samples": int(len(g)), "grids": {}}
    for name in ("density", "color"):
        grid = getattr(fld, name).detach().clone().requires_grad_(True)
        up = torch.randn(grid.shape[1], len(g), generator=torch.Generator().manual_seed(2))
        ways = {"grid_sample": lambda: F.grid_sample(grid, g.reshape(1, 1, 1, -1, 3), mode="bilinear",
                                                     align_corners=True).reshape(grid.shape[1], -1),
                "index_add": lambda: trilinear(grid, trilinear_corners(g, fld.res))}
        res, vals = {}, {}
        for way, fn in ways.items():
            fwd, bwd = [], []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                v = fn()
                t1 = time.perf_counter()
                (v * up).sum().backward()
                bwd.append(time.perf_counter() - t1)
                fwd.append(t1 - t0)
                vals[way] = (v.detach(), grid.grad.clone())
                grid.grad = None
            res[way] = {"forward_ms": round(1e3 * float(np.median(fwd)), 2),
                        "backward_ms": round(1e3 * float(np.median(bwd)), 2)}
        (va, ga), (vb, gb) = vals["grid_sample"], vals["index_add"]
        res["max_value_diff"] = float((va - vb).abs().max())
        res["max_grad_diff"] = float((ga - gb).abs().max())
        res["channels"] = int(grid.shape[1])
        out["grids"][name] = res
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
