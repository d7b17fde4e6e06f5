"""Which distance from a held-out view to its nearest chosen view predicts its PSNR best?

View medoids minimise the mean of ``d = |c_i - c_j| + w |a_i - a_j|`` (w = 1; c the camera
centre, a the look-at point) from each pool view to its nearest chosen view. This reads
every trained unit of a harness run folder (``python3 -m research.harness --out
DIR`` writes ``DIR/<scene>/evaluate/q_*``) and asks how well the nearest chosen view, in
``d`` with another look weight ``w`` and through a cost ``g`` (``d``, ``sqrt d``,
``log(1 + d / tau)``, tau the pool's median nearest-view distance), predicts each held-out
view's PSNR *across the subsets trained for the same fold and budget*: PSNR and g(d) are
centred per held-out view (what makes a view hard drops out), and the table gives the
share of the remaining variance that g(d) explains (r^2), best first. One more row
(w = 1, cost ``d, d2``) fits the nearest *and* the second-nearest chosen view's distance
together: how much a second view close by adds to what the nearest one explains.

Off-path test views (the synthetic room) are listed apart (``--part off``).

The last line is JSON. Example::

    python research/view_distance_fit.py --run .gpudata/quality/office
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def centred_r2(groups: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """r^2 of PSNR on one or more features, all centred within each group.

    groups: [(psnr [n], features [n] or [n, f])]. Least squares without intercept on the
    centred values; with one feature this is the squared correlation. 0 where PSNR or
    every feature is constant within every group.
    """
    def centred(a):                                              # [n] or [n, f] -> [n, f], mean 0
        a = np.asarray(a, float).reshape(len(a), -1)
        return a - a.mean(0)
    y = np.concatenate([centred(p)[:, 0] for p, _ in groups])  # [N]
    x = np.concatenate([centred(f) for _, f in groups])        # [N, f]
    if not (y @ y > 0 and np.any(x != 0)):
        return 0.0
    beta, *_ = np.linalg.lstsq(x, y, rcond=None)
    res = y - x @ beta
    return float(np.clip(1.0 - (res @ res) / (y @ y), 0.0, 1.0))


def nearest_two(d: np.ndarray) -> np.ndarray:
    """[1, n] distances to the chosen views -> [2]: the nearest and the second nearest
    (the nearest twice when only one view is chosen)."""
    d = np.sort(np.ravel(d))
    return np.array([d[0], d[min(1, len(d) - 1)]])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="a harness scene folder (sfm/, occupancy/, evaluate/q_*)")
    ap.add_argument("--weights", default="0.1,0.2,0.3,0.5,1,2", help="look weights w to try")
    ap.add_argument("--part", default="on", choices=("on", "off"), help="test views on the path or off it")
    args = ap.parse_args(argv)

    from research.harness import UNIT_KEY                 # the harness's unit folder names
    from curate.select.medoids import embed, view_depths
    from curate.core.run import load_node_grid
    from curate.select.config import SelectConfig
    from curate.sfm.io import load_sfm
    from curate.select.visibility import build_pair_index
    run = Path(args.run)
    cams = load_sfm(run).cameras
    n_reg = len(cams)
    if (run / "offpath.json").is_file():                      # the room: its off-path test views after the walk
        from curate.core.cameras import Cameras
        from curate.core.transforms_json import read_transforms
        cams = Cameras.concat([cams, read_transforms(run / "offpath.json")[0]])
    at = {Path(n).name: i for i, n in enumerate(cams.names)}
    grid = load_node_grid(run)
    depth = view_depths(cams, grid.nodes(), build_pair_index(cams, grid.nodes(), SelectConfig().energy.bins))
    c, a = embed(cams, depth)                                  # [N, 3] centres, [N, 3] look-at points

    views = defaultdict(list)                                  # (budget, fold, view) -> [(psnr, chosen)]
    for f in sorted((run / "evaluate").glob("q_*/metrics.json")):
        m = UNIT_KEY.match(f.parent.name)
        if not m or m["label"] == "oracle" or m["seed"] != "0":   # the oracle sees the test
            continue
        rec = json.loads(f.read_text())
        chosen = np.asarray(rec["subset"], np.int64)
        for pv in rec["per_view"]:
            h = at[Path(pv["name"]).name]
            if (h >= n_reg) == (args.part == "off"):
                views[(int(m["budget"]), int(m["fold"] or 0), h)].append((float(pv["psnr"]), chosen))
    views = {k: g for k, g in views.items() if len(g) >= 3}
    if not views:
        raise SystemExit(f"{run}: no held-out view with 3 or more trained subsets")
    def parts(rows_c, rows_a, cols):                          # centre and look-at distances [r, len(cols)]
        return (np.linalg.norm(rows_c[:, None] - c[cols][None], axis=2),
                np.linalg.norm(rows_a[:, None] - a[cols][None], axis=2))

    reg = np.arange(n_reg)
    dc_pool, da_pool = parts(c[:n_reg], a[:n_reg], reg)        # [K, K] each, every w reuses them
    np.fill_diagonal(dc_pool, np.inf)
    to_chosen = {k: [parts(c[k[2]][None], a[k[2]][None], ch) for _, ch in g] for k, g in views.items()}
    psnr = {k: np.array([p for p, _ in g]) for k, g in views.items()}
    rows = []
    for w in [float(x) for x in args.weights.split(",") if x]:
        tau = float(np.median((dc_pool + w * da_pool).min(1)))
        near = {k: np.array([(dc + w * da).min() for dc, da in ds]) for k, ds in to_chosen.items()}
        for cost, fn in (("d", lambda d: d), ("sqrt", np.sqrt), ("log", lambda d: np.log1p(d / tau))):
            rows.append({"w": w, "cost": cost, "r2": round(centred_r2([(psnr[k], fn(near[k])) for k in views]), 4)})
        if w == 1:                                             # nearest and second-nearest chosen view
            two = {k: np.array([nearest_two(dc + da) for dc, da in ds]) for k, ds in to_chosen.items()}
            rows.append({"w": w, "cost": "d, d2", "r2": round(centred_r2([(psnr[k], two[k]) for k in views]), 4)})
    rows.sort(key=lambda r: -r["r2"])
    print(f"{run.name} ({args.part} the path): {len(views)} held-out views with >= 3 trained subsets, "
          f"{sum(len(g) for g in views.values())} (view, subset) pairs")
    print(f"{'w':>5s} {'cost':>5s} {'r2':>7s}")
    for r in rows:
        mark = "   <- view medoids" if r["w"] == 1 and r["cost"] == "d" else ""
        print(f"{r['w']:5.2f} {r['cost']:>5s} {r['r2']:7.3f}{mark}")
    print(json.dumps({"run": str(run), "part": args.part, "views": len(views), "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
