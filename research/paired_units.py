"""Two methods of one harness scene folder, paired per held-out view over every fold both have.

Reads the trained units ``RUN/evaluate/q_<label>_b<budget>_t<seed>[_o<fold>]`` of two labels
(a method's per-view PSNR averaged over its training seeds), pairs them by fold and view, and
prints per fold the mean difference and the folds pooled (a paired 95% t interval over the
concatenated views). For a comparison whose units were trained at different times, e.g. the
default before and after a change (``--b default-21b682``).

    python3 -m research.paired_units --run /tmp/hpoff/office --a pathstride_l05 --b default-21b682 [--budget 59]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from curate.core.stats import mean_ci


def units(run: Path, label: str, budget: int | None = None) -> dict[tuple[int, int], list[dict]]:
    """{(budget, fold): [per-view {name: PSNR} of each training seed]} of ``label`` in ``run``."""
    from research.gap_closed import per_view
    from research.harness import UNIT_KEY
    out: dict = {}
    for d in sorted((run / "evaluate").glob("q_*")):
        m = UNIT_KEY.match(d.name)
        if not m or m["label"] != label or m["draw"] or not (d / "metrics.json").is_file():
            continue
        b = int(m["budget"])
        if budget is None or b == budget:
            out.setdefault((b, int(m["fold"] or 0)), []).append(per_view(d / "metrics.json"))
    return out


def paired(run: Path, a: str, b: str, budget: int | None = None) -> list[dict]:
    """One row per budget: per-fold mean differences ``a - b`` and the folds pooled."""
    ua, ub = units(run, a, budget), units(run, b, budget)
    rows = []
    for bud in sorted({k[0] for k in ua} & {k[0] for k in ub}):
        diffs, folds = [], []
        for key in sorted(k for k in ua if k[0] == bud and k in ub):
            names = sorted(set.intersection(*(set(v) for v in ua[key] + ub[key])))
            va = np.mean([[u[n] for n in names] for u in ua[key]], axis=0)
            vb = np.mean([[u[n] for n in names] for u in ub[key]], axis=0)
            diffs.append(va - vb)
            folds.append({"fold": key[1], "views": len(names), "a": round(float(va.mean()), 3),
                          "b": round(float(vb.mean()), 3), "diff": round(float((va - vb).mean()), 3)})
        if not diffs:
            continue
        ci = mean_ci(np.concatenate(diffs))
        n = sum(f["views"] for f in folds)
        rows.append({"budget": bud, "folds": folds, "views": n,
                     "a": round(sum(f["a"] * f["views"] for f in folds) / n, 3),
                     "b": round(sum(f["b"] * f["views"] for f in folds) / n, 3),
                     "diff": {k: round(float(ci[k]), 3) for k in ("mean", "lo", "hi")},
                     "folds_ahead": int(sum(f["diff"] > 0 for f in folds))})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="a harness scene folder (OUT/<scene>)")
    ap.add_argument("--a", required=True, help="unit label, e.g. pathstride_l05")
    ap.add_argument("--b", required=True, help="unit label, e.g. default-21b682")
    ap.add_argument("--budget", type=int, default=None)
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    rows = paired(args.run, args.a, args.b, args.budget)
    if not rows:
        print(f"no fold where both {args.a} and {args.b} are trained in {args.run}", file=sys.stderr)
        return 1
    print(f"| budget | folds (views) | `{args.a}` | `{args.b}` | difference (95% CI) | folds ahead | per fold |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        d = r["diff"]
        per = ", ".join(f"{f['fold']}: {f['diff']:+.2f}" for f in r["folds"])
        print(f"| {r['budget']} | {len(r['folds'])} ({r['views']}) | {r['a']:.2f} | {r['b']:.2f} | "
              f"{d['mean']:+.2f} ({d['lo']:+.2f} to {d['hi']:+.2f}) | {r['folds_ahead']} of {len(r['folds'])} "
              f"| {per} |")
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
