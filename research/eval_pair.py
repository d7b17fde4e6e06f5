"""Two evaluations of one run folder's capture, each made by another build of curate: the same trainings, what each
cost, what each scored, and the verdicts.

    cp -a RUN RUN_A; cp -a RUN RUN_B
    (cd BUILD_A && python -m curate evaluate RUN_A); (cd BUILD_B && python -m curate evaluate RUN_B)
    python -m research.eval_pair RUN_A RUN_B

Run each build from its own checkout: ``python -m`` puts the working directory first on the path, so
``PYTHONPATH=BUILD_A python -m curate ...`` run from another checkout imports that checkout's curate (and so do the
evaluation's spawned workers).

Prints one JSON object: per training both builds made (``RUN/evaluate/<unit>/metrics.json``), its CPU seconds under
each and the largest difference of a held-out photo's PSNR; the CPU seconds of the trainings in common and of all,
and their ratio (B over A), a unit copied from another counted as costing nothing; each rival's difference (mean
and interval) and decision under each; the folds each took. What a change that should only make the trainings
cheaper must leave the same: the PSNRs to float rounding, and so the verdicts.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def units(run: Path) -> dict[str, dict]:
    """{unit folder name: its metrics.json} of a run folder's evaluation."""
    from curate.evaluate.units import read_metrics
    return {p.parent.name: read_metrics(p.parent) for p in sorted((run / "evaluate").glob("*/metrics.json"))}


def cost(m: dict, key: str) -> float:
    """A unit's ``cpu_seconds`` or ``train_seconds``; 0 for a unit copied from another (it carries the source's
    figures, and cost nothing)."""
    return 0.0 if m.get("copied_from") else m[key]


def verdicts(run: Path) -> dict:
    """Each rival's difference, interval and decision, and the folds, from ``RUN/evaluate/summary.json``."""
    s = json.loads((run / "evaluate" / "summary.json").read_text())
    out = {k: {"mean": round(v["mean"], 4), "lo": round(v["lo"], 4), "hi": round(v["hi"], 4),
               "n_folds": v["n_folds"], "decision": v["decision"]} for k, v in s["paired"].items()}
    return {"rivals": out, "n_folds": s["protocol"]["n_folds"], "stopped": s["protocol"]["stopped"]}


def compare(a: Path, b: Path) -> dict:
    ua, ub = units(a), units(b)
    common = sorted(set(ua) & set(ub))
    rows = []
    for k in common:
        va = {r["name"]: r["psnr"] for r in ua[k]["per_view"]}
        vb = {r["name"]: r["psnr"] for r in ub[k]["per_view"]}
        dv = max((abs(va[n] - vb[n]) for n in va.keys() & vb.keys()), default=None)
        rows.append({"unit": k, "cpu_a": cost(ua[k], "cpu_seconds"), "cpu_b": cost(ub[k], "cpu_seconds"),
                     "train_a": cost(ua[k], "train_seconds"), "train_b": cost(ub[k], "train_seconds"),
                     "copied": [x for x, u in (("a", ua[k]), ("b", ub[k])) if u.get("copied_from")],
                     "max_view_psnr_diff": dv})
    ca, cb = sum(r["cpu_a"] for r in rows), sum(r["cpu_b"] for r in rows)
    ta, tb = sum(r["train_a"] for r in rows), sum(r["train_b"] for r in rows)
    return {"a": str(a), "b": str(b), "units": rows, "common": len(common),
            "only_a": sorted(set(ua) - set(ub)), "only_b": sorted(set(ub) - set(ua)),
            "cpu_common": {"a": round(ca, 1), "b": round(cb, 1), "b_over_a": round(cb / ca, 3) if ca else None},
            "train_common": {"a": round(ta, 1), "b": round(tb, 1), "b_over_a": round(tb / ta, 3) if ta else None},
            "cpu_all": {"a": round(sum(cost(u, "cpu_seconds") for u in ua.values()), 1),
                        "b": round(sum(cost(u, "cpu_seconds") for u in ub.values()), 1)},
            "max_view_psnr_diff": max((r["max_view_psnr_diff"] or 0.0 for r in rows), default=None),
            "verdicts": {"a": verdicts(a), "b": verdicts(b)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path, help="the run folder evaluated by the first build (the reference)")
    ap.add_argument("b", type=Path, help="the same run folder's copy evaluated by the second build")
    args = ap.parse_args(argv)
    print(json.dumps(compare(args.a, args.b)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
