"""Per kind of walk: a candidate selection against its rivals, pooled over the rooms and seeds of
each kind, with the worst scene and a correction for the number of comparisons.

Issue 25 judges a default per *kind* of walk (a loop, a corridor, turning on the spot, ...), not
per scene: one scene is one room and one trajectory, and its per-view intervals say nothing of
how another room would go. This reads the trained units of harness scene folders
(``walk-<kind>[-<room>][-s<seed>]``, fold 0; a method's per-view PSNR is averaged over its
training seeds, random over its draws) and, per kind, budget (as a share of the pool) and part
(``path``: the held-out frames; ``off``: the free-space views off the path; budgets are the
units' counts, so the scenes of a kind must have pools of one size, as the harness's walks do),
pools the per-view
differences of every scene of the kind (a paired t interval over the concatenated views).

A kind is *behind* a rival when the pooled interval lies below 0; with many kinds, budgets,
parts and rivals, some intervals exclude 0 by chance, so each such loss is also tested with
Holm's step-down correction over the whole family (``holm``: still significant after it).

    python3 -m research.walk_kinds --out /tmp/h25 [--out /tmp/h26 ...] --candidate default \
        [--rivals stride,fvs,random] [--json F]
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from curate.core.stats import mean_ci


def scene_units(run: Path) -> tuple[dict, dict | None]:
    """({budget: {method label: [per-view dict, ...]}}, per-view dict of 'all' or None) of one
    harness scene folder, fold 0. Labels: the unit folders' (``default-<hash>`` is ``default``)."""
    from research.gap_closed import per_view
    from research.harness import UNIT_KEY
    ev = run / "evaluate"
    units: dict = {}
    for d in sorted(ev.glob("q_*")):
        m = UNIT_KEY.match(d.name)
        if not m or m["fold"] or not (d / "metrics.json").is_file():
            continue
        label = "default" if m["label"].startswith("default-") else m["label"]
        units.setdefault(int(m["budget"]), {}).setdefault(label, []).append(per_view(d / "metrics.json"))
    a = ev / "all" / "metrics.json"
    return units, (per_view(a) if a.is_file() else None)


def p_two_sided(x) -> float:
    """Two-sided one-sample t-test p-value of mean(x) = 0 (1.0 when undefined)."""
    from scipy.stats import t
    x = np.asarray(x, float)
    if x.size < 2 or not np.std(x) > 0:
        return 1.0
    tt = x.mean() / (x.std(ddof=1) / math.sqrt(x.size))
    return float(2 * t.sf(abs(tt), x.size - 1))


def holm(pvalues: list[float], alpha: float = 0.05) -> list[bool]:
    """Holm's step-down test: which of the hypotheses are rejected at family-wise level ``alpha``."""
    order = np.argsort(pvalues, kind="stable")
    out = [False] * len(pvalues)
    for rank, i in enumerate(order):
        if pvalues[i] > alpha / (len(pvalues) - rank):
            break
        out[i] = True
    return out


def cells(runs: list[Path], candidate: str, rivals: list[str]) -> list[dict]:
    """One record per scene, budget and part where the candidate, every rival and 'all' exist:
    per-view PSNR arrays of each method (over the part's views) and the scene's kind."""
    from research.harness import walk_spec
    out = []
    for run in runs:
        spec = walk_spec(run.name)
        units, a = scene_units(run)
        if spec is None or a is None:
            continue
        for b, us in sorted(units.items()):
            if candidate not in us or any(r not in us for r in rivals):
                continue
            for part in ("path", "off"):
                keys = [k for k in a if ("offpath" in k) == (part == "off")]
                if len(keys) < 2:
                    continue
                v = {m: np.mean([[u[k] for k in keys] for u in us[m]], axis=0) for m in [candidate, *rivals]}
                v["all"] = np.array([a[k] for k in keys])
                out.append({"scene": run.name, "kind": spec[0], "budget": b, "part": part, "psnr": v})
    return out


def kind_table(records: list[dict], candidate: str, rivals: list[str]) -> list[dict]:
    """Pooled per (kind, budget, part): candidate - rival over the concatenated views, the worst
    scene's mean difference, gap closed (candidate - random over all - random, pooled), the p-value."""
    groups: dict = {}
    for r in records:
        groups.setdefault((r["kind"], r["budget"], r["part"]), []).append(r)
    rows = []
    for (kind, b, part), rs in sorted(groups.items()):
        row = {"kind": kind, "budget": b, "part": part, "scenes": [r["scene"] for r in rs],
               "views": int(sum(len(r["psnr"]["all"]) for r in rs))}
        cat = {m: np.concatenate([r["psnr"][m] for r in rs]) for m in [candidate, *rivals, "all"]}
        row["psnr"] = {m: round(float(v.mean()), 3) for m, v in cat.items()}
        for o in rivals:
            d = cat[candidate] - cat[o]
            ci = mean_ci(d)
            row[f"vs_{o}"] = {"mean": round(ci["mean"], 3), "lo": round(ci["lo"], 3), "hi": round(ci["hi"], 3),
                              "p": p_two_sided(d),
                              "worst_scene": round(min(float(np.mean(r["psnr"][candidate] - r["psnr"][o]))
                                                       for r in rs), 3)}
        if "random" in rivals:
            room = float(cat["all"].mean() - cat["random"].mean())
            row["gap_closed"] = (round(float(cat[candidate].mean() - cat["random"].mean()) / room, 3)
                                 if room > 1e-6 else None)
        rows.append(row)
    fam = [(i, o) for i, r in enumerate(rows) for o in rivals if o != "random"]
    rej = holm([rows[i][f"vs_{o}"]["p"] for i, o in fam])
    for (i, o), h in zip(fam, rej):
        rows[i][f"vs_{o}"]["holm"] = bool(h)
    return rows


def fmt(d: dict) -> str:
    s = f"{d['mean']:+.2f} ({d['lo']:+.2f} to {d['hi']:+.2f})"
    s = f"**{s}**" if d["lo"] > 0 or d["hi"] < 0 else s
    return s + (" †" if d.get("holm") and d["mean"] < 0 else "")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, action="append", required=True, help="harness --out folder(s)")
    ap.add_argument("--candidate", default="default", help="unit label of the method judged")
    ap.add_argument("--rivals", default="stride,fvs,random")
    ap.add_argument("--scenes", default="", help="only these scene folders (comma list)")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--all-kinds", action="store_true",
                    help="one more row per budget and part: every kind pooled (not in the Holm family)")
    args = ap.parse_args(argv)
    rivals = [r for r in args.rivals.split(",") if r and r != args.candidate]
    only = {s for s in args.scenes.split(",") if s}
    runs = [p for o in args.out for p in sorted(o.iterdir())
            if (p / "evaluate").is_dir() and (not only or p.name in only)]
    recs = cells(runs, args.candidate, rivals)
    if not recs:
        print(f"no walk scene with trained 'all', {args.candidate} and {', '.join(rivals)} units", file=sys.stderr)
        return 1
    rows = kind_table(recs, args.candidate, rivals)
    pooled = kind_table([dict(r, kind="all kinds") for r in recs], args.candidate, rivals) if args.all_kinds else []
    for r in pooled:                                     # not part of the family Holm corrects
        for o in rivals:
            r[f"vs_{o}"].pop("holm", None)
    c = "`auto`" if args.candidate == "default" else f"`{args.candidate}`"
    print(f"| kind | budget | part | scenes (views) | {c} | " + " | ".join(f"{c} - {o}" for o in rivals)
          + " | worst scene vs " + ", ".join(o for o in rivals if o != "random") + " | gap closed |")
    print("|---" * (6 + len(rivals)) + "|")
    for r in rows + pooled:
        worst = ", ".join(f"{r[f'vs_{o}']['worst_scene']:+.2f}" for o in rivals if o != "random")
        gap = "-" if r.get("gap_closed") is None else f"{100 * r['gap_closed']:.0f}%"
        print(f"| {r['kind']} | {r['budget']} | {r['part']} | {len(r['scenes'])} ({r['views']}) | "
              f"{r['psnr'][args.candidate]:.2f} | " + " | ".join(fmt(r[f"vs_{o}"]) for o in rivals)
              + f" | {worst} | {gap} |")
    behind = [(r["kind"], r["budget"], r["part"], o) for r in rows for o in rivals
              if o != "random" and r[f"vs_{o}"]["hi"] < 0]
    held = [x for x in behind if rows[[(r["kind"], r["budget"], r["part"]) for r in rows].index(x[:3])]
            [f"vs_{x[3]}"]["holm"]]
    print(f"\n{len(rows)} kind cells; {args.candidate} significantly behind a rival in {len(behind)} "
          f"({', '.join(f'{k} {b} {p} vs {o}' for k, b, p, o in behind) or 'none'}); "
          f"after Holm's correction over {sum(1 for r in rows for o in rivals if o != 'random')} comparisons: "
          f"{len(held)} († in the table)")
    if args.json:
        args.json.write_text(json.dumps({"candidate": args.candidate, "rivals": rivals, "rows": rows,
                                         "behind": behind, "behind_holm": held, "all_kinds": pooled}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
