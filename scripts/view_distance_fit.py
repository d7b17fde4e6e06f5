"""Which distance from a held-out view to its nearest chosen view predicts its PSNR best?

View medoids minimise the mean of ``d = |c_i - c_j| + w |a_i - a_j|`` (w = 1; c the camera
centre, a the look-at point) from each pool view to its nearest chosen view. This reads
every trained unit of a harness run folder (``scripts/bench_selection_quality.py --out
DIR`` writes ``DIR/<scene>/evaluate/q_*``) and asks how well the nearest chosen view, in
``d`` with another look weight ``w`` and through a cost ``g`` (``d``, ``sqrt d``,
``log(1 + d / tau)``, tau the pool's median nearest-view distance), predicts each held-out
view's PSNR *across the subsets trained for the same fold and budget*: PSNR and g(d) are
centred per held-out view (what makes a view hard drops out), and the table gives the
share of the remaining variance that g(d) explains (r^2), best first.

Off-path test views (the synthetic room) are listed apart (``--part off``).

The last line is JSON. Example::

    python scripts/view_distance_fit.py --run .gpudata/quality/office
"""

from __future__ import annotations

import argparse
import json
import sys
from collections import defaultdict
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))


def centred_r2(groups: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """r^2 between PSNR and a feature, both centred within each group [(psnr [n], feature [n])]."""
    y = np.concatenate([p - p.mean() for p, _ in groups])
    x = np.concatenate([f - f.mean() for _, f in groups])
    if not (x @ x > 0 and y @ y > 0):
        return 0.0
    return float((x @ y) ** 2 / ((x @ x) * (y @ y)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", required=True, help="a harness scene folder (sfm/, occupancy/, evaluate/q_*)")
    ap.add_argument("--weights", default="0.1,0.2,0.3,0.5,1,2", help="look weights w to try")
    ap.add_argument("--part", default="on", choices=("on", "off"), help="test views on the path or off it")
    args = ap.parse_args(argv)

    from bench_selection_quality import UNIT_KEY                 # the harness's unit folder names
    from curate.medoids import embed, view_depths
    from curate.pipeline import load_node_grid
    from curate.select import SelectConfig
    from curate.sfm_io import load_sfm
    from curate.visibility import build_pair_index
    run = Path(args.run)
    cams = load_sfm(run).cameras
    n_reg = len(cams)
    if (run / "offpath.json").is_file():                      # the room: its off-path test views after the walk
        from curate.cameras import Cameras
        from curate.transforms_json import read_transforms
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
