"""Issue 25's pre-registered choice of the walk rule among candidates, as code.

On the chosen scenes and budget, for each candidate: per kind of walk and part (on the path,
off it), pooled over the rooms of the kind (:mod:`research.walk_kinds`), the paired
difference to each *rival* (the current default, every n-th frame, FVS; the candidate itself
excluded). Ranked by, in order:

1. the number of kind cells where the candidate is significantly behind any rival (fewest);
2. the worst pooled difference to a rival over every kind cell (highest);
3. the mean over the kind cells of the difference to the current default (highest).

    python3 -m research.choose_walk_rule --out /tmp/hp --scenes S1,S2,... \
        --candidates default,stride,pathstride,... [--rivals default,stride,fvs] [--json F]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from research.walk_kinds import cells, kind_table


def score(runs: list[Path], candidate: str, rivals: list[str]) -> dict:
    """The three ranking figures of ``candidate`` against ``rivals`` (itself excluded)."""
    rv = [r for r in rivals if r != candidate]
    rows = kind_table(cells(runs, candidate, rv), candidate, rv)
    if not rows:
        return {"candidate": candidate, "cells": 0}
    behind = sorted({(r["kind"], r["part"]) for r in rows for o in rv if r[f"vs_{o}"]["hi"] < 0})
    worst = min((r[f"vs_{o}"]["mean"], r["kind"], r["part"], o) for r in rows for o in rv)
    vs_default = (float(np.mean([r["vs_default"]["mean"] for r in rows])) if "default" in rv else 0.0)
    return {"candidate": candidate, "cells": len(rows), "scenes": len({s for r in rows for s in r["scenes"]}),
            "cells_behind": len(behind), "behind": [f"{k} {p}" for k, p in behind],
            "worst": round(worst[0], 3), "worst_cell": f"{worst[1]} {worst[2]} vs {worst[3]}",
            "mean_vs_default": round(vs_default, 3)}


def rank(scores: list[dict]) -> list[dict]:
    """``scores`` best first by the rule of the module docstring (candidates measured on fewer
    scenes or kind cells than the most complete one are left out: they could not be compared)."""
    full = max((s["cells"], s.get("scenes", 0)) for s in scores)
    ok = [s for s in scores if (s["cells"], s.get("scenes", 0)) == full and full[0] > 0]
    return sorted(ok, key=lambda s: (s["cells_behind"], -s["worst"], -s["mean_vs_default"]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, action="append", required=True)
    ap.add_argument("--scenes", default="")
    ap.add_argument("--candidates", required=True)
    ap.add_argument("--rivals", default="default,stride,fvs")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    only = {s for s in args.scenes.split(",") if s}
    runs = [p for o in args.out for p in sorted(o.iterdir())
            if (p / "evaluate").is_dir() and (not only or p.name in only)]
    rivals = [r for r in args.rivals.split(",") if r]
    scores = [score(runs, c, rivals) for c in args.candidates.split(",") if c]
    ranked = rank(scores)
    print("| rank | candidate | scenes | kind cells | cells behind a rival | worst difference (cell) "
          "| mean vs `auto` |")
    print("|---|---|---|---|---|---|---|")
    for i, s in enumerate(ranked, 1):
        print(f"| {i} | `{s['candidate']}` | {s['scenes']} | {s['cells']} | {s['cells_behind']}"
              f"{' (' + ', '.join(s['behind']) + ')' if s['behind'] else ''} | {s['worst']:+.2f} ({s['worst_cell']}) | "
              f"{s['mean_vs_default']:+.3f} |")
    left = [s["candidate"] for s in scores if s not in ranked]
    if left:
        print(f"\nnot ranked (measured on fewer scenes or kind cells): {', '.join(left)}")
    if args.json:
        args.json.write_text(json.dumps({"ranked": ranked, "not_ranked": left}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
