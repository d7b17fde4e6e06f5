"""CPU seconds per decision, before and after issue 59, from trainings measured on real captures.

For each capture, two sibling run folders of the agreement study (``research/eval_agreement.py``): ``--old``, the
field before (160 px, 400 iterations, 4,096 rays: its trainings give the CPU seconds a training cost), and
``--new``, the evaluation's field now, trained over many folds (its per-view differences: what the folds show).

* **before**: the procedure of 0.3 before this change, replayed on the new field's per-view differences (they
  correlate 0.99 with the old field's, docs/evaluation.md): every rival trained in every fold, all photos in the
  first two folds, looks after 4 folds and at the end (the cluster-robust interval, t on folds - 1, 97.5%), a fold
  started only while ``--minutes`` hold it on ``--cores`` (each training the old field's median CPU seconds);
* **after**: the product's evaluation itself (:mod:`curate.evaluate.stage`, today's defaults) run on a copy of the
  ``--new`` sibling whose trainings are all there (reused, so it runs in seconds): the folds and trainings it
  uses until decided, each costing the CPU seconds its unit recorded. Its time limit is not replayed (reused
  trainings cost no time): ``--minutes`` is checked against the CPU seconds it used over ``--cores``.
  The trainings counted are those ``summary.json`` lists per fold: since issue 59's item 3 only the ones trained
  or reused (before, a fold listed the trainings its plan left out too, and this count included them).

Printed per capture: folds, trainings and CPU seconds until the verdict, before and after, and each verdict.
One JSON line last.

    python -m research.decision_cost --old /tmp/agree/office@160x400 --new /tmp/agree/office@NEW --out /tmp/cost
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np


def unit_cpu(sib: Path) -> dict[str, float]:
    """{unit key: CPU seconds} of the trained (not copied) units of a sibling."""
    out = {}
    for m in (sib / "evaluate").glob("f*/metrics.json"):
        d = json.loads(m.read_text())
        if d.get("cpu_seconds") is not None and not d.get("copied_from"):
            out[m.parent.name] = float(d["cpu_seconds"])
    return out


def trained_field(sib: Path):
    """The FieldConfig a sibling's units were trained with (as recorded in a unit's stage record)."""
    from curate.field.config import FieldConfig
    rec = json.loads(next((sib / "evaluate").glob("f*/stage.json")).read_text())
    return FieldConfig.from_dict(rec["config"]["field"])


def per_fold_diffs(summary: dict) -> dict[str, list[np.ndarray]]:
    from research.interval_study import fold_diffs
    return {r: fold_diffs(summary, r) for r in ("random", "fvs", "stride")}


def before(diffs: dict, old_s: float, minutes: float, cores: int, has_stride: bool) -> dict:
    """The 0.3 procedure before issue 59 on ``diffs`` (per rival, per fold in order)."""
    from curate.core.stats import decision, folds_paired
    n_folds = min(len(v) for v in diffs.values() if v)
    per_fold = [(3 + has_stride + (1 if f < 2 else 0)) * old_s for f in range(n_folds)]   # 'all' in two folds
    budget = 60 * minutes * cores
    spent, F = 0.0, 0
    looks = [4, n_folds]
    while F < n_folds:
        if F >= 2 and spent + per_fold[F] > budget:
            break
        spent += per_fold[F]
        F += 1
        if F in looks or F == n_folds:
            dec = {r: decision(folds_paired(v[:F], 0.975), 0.3) for r, v in diffs.items() if v}
            if all(d != "undecided" for d in dec.values()):
                return {"folds": F, "cpu_s": spent, "decided": True, "verdicts": dec}
    dec = {r: decision(folds_paired(v[:F], 0.975), 0.3) for r, v in diffs.items() if v}
    return {"folds": F, "cpu_s": spent, "decided": all(d != "undecided" for d in dec.values()), "verdicts": dec}


def after(new: Path, out: Path, minutes: float) -> dict:
    """The product's evaluation on a copy of ``new`` (every training reused)."""
    from dataclasses import replace

    from curate.pipeline import saved_config
    from curate.core import runfolder
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.evaluate.config import EvalConfig
    dst = out / new.name
    if dst.exists():
        shutil.rmtree(dst)
    shutil.copytree(new, dst, symlinks=True)
    for f in ("summary.json", "stage.json"):
        (dst / "evaluate" / f).unlink(missing_ok=True)
    cfg, _ = saved_config(dst)
    d = EvalConfig()
    field = trained_field(new)          # the sibling's own field settings, as its units were keyed
    cfg = replace(cfg, evaluate=replace(cfg.evaluate, folds=0, minutes=minutes, methods=d.methods,
                                        random_seeds=d.random_seeds, max_side=d.max_side, iters=d.iters,
                                        field=field))
    with runfolder.claimed(dst, writes=("evaluate",)):
        run_stage(BY_NAME["evaluate"], RunContext(cfg, dst))
    s = json.loads((dst / "evaluate" / "summary.json").read_text())
    cpu = unit_cpu(new)
    used = [k for f in s["protocol"]["folds"] for k in f["units"]]
    return {"folds": s["protocol"]["n_folds"], "trainings": len([k for k in used if k in cpu]),
            "cpu_s": float(sum(cpu.get(k, 0.0) for k in used)), "stopped": s["protocol"]["stopped"],
            "verdicts": {k.split("-", 1)[1]: p["decision"] for k, p in s["paired"].items()},
            "intervals": {k.split("-", 1)[1]: [round(p["mean"], 2), round(p["lo"], 2), round(p["hi"], 2)]
                          for k, p in s["paired"].items() if p.get("lo") is not None}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", type=Path, nargs="+", required=True)
    ap.add_argument("--new", type=Path, nargs="+", required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--minutes", type=float, default=15.0)
    ap.add_argument("--cores", type=int, default=2)
    a = ap.parse_args(argv)
    rows = []
    a.out.mkdir(parents=True, exist_ok=True)
    for old, new in zip(a.old, a.new):
        old_s = float(np.median(list(unit_cpu(old).values())))
        new_s = float(np.median(list(unit_cpu(new).values())))
        summ = json.loads((new / "evaluate" / "summary.json").read_text())
        diffs = per_fold_diffs(summ)
        b = before(diffs, old_s, a.minutes, a.cores, bool(diffs["stride"]))
        n = after(new, a.out, a.minutes)
        row = {"capture": new.name.split("@")[0], "old_s_per_training": old_s, "new_s_per_training": new_s,
               "before": b, "after": n, "ratio": b["cpu_s"] / n["cpu_s"] if n["cpu_s"] else None}
        rows.append(row)
        print(f"{row['capture']}: a training {old_s:.1f} -> {new_s:.1f} CPU s; before: {b['folds']} folds, "
              f"{b['cpu_s']:.0f} CPU s, {'decided' if b['decided'] else 'undecided'} {b['verdicts']}; after: "
              f"{n['folds']} folds, {n['trainings']} trainings, {n['cpu_s']:.0f} CPU s, {n['stopped']} "
              f"{n['verdicts']}; {row['ratio']:.1f}x fewer CPU seconds", flush=True)
    print(json.dumps({"minutes": a.minutes, "cores": a.cores, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
