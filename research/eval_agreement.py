"""Does a cheaper evaluation field give the same verdict? (issue 48, part 2)

For each run folder (SfM, occupancy and selection done) and each training setting, the product's evaluation
(:mod:`curate.evaluate.stage`) trains the first ``--folds`` hold-out folds with that setting, in a sibling
run folder ``<out>/<capture>@<setting>`` that shares the run's SfM, occupancy and selection (hard links) and
has its own ``evaluate/``. Then, per capture and rival, the per-view differences (selection - rival) of each
setting against the reference setting (the first): their correlation, the mean difference and its interval
under each, whether the decisions agree, and each setting's CPU seconds per training.

Usage:
  python -m research.eval_agreement RUN... --out /tmp/agree --settings 240x800,160x400,160x250 --folds 2
Prints one table per capture and one JSON line last. ``--reread DIR`` trains nothing: the table from the
first two folds' summaries saved in DIR (``<capture>@<setting>.summary.json``), decisions read with today's
interval.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

SHARED = ("sfm", "occupancy", "select", "run.json", ".curate-run.json")


def sibling(run: Path, dest: Path) -> Path:
    """``dest``: a run folder sharing ``run``'s SfM, occupancy and selection (hard links; copies across devices)."""
    if (dest / "select" / "stage.json").is_file():
        return dest
    dest.mkdir(parents=True, exist_ok=True)
    for name in SHARED:
        src = run / name
        if src.is_dir():
            shutil.copytree(src, dest / name, copy_function=_link, dirs_exist_ok=True, symlinks=True)
        elif src.is_file():
            _link(src, dest / name)
    return dest


def _link(src, dst) -> None:
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def setting(text: str) -> tuple[int, int, dict]:
    """'160x400' -> (max_side 160, iters 400, {}); '160x400+batch_rays=2048+n_inner=48' also sets those fields of
    the evaluation's FieldConfig (numbers as numbers)."""
    head, *sets = text.split("+")
    a, b = head.lower().split("x")
    over = {}
    for kv in sets:
        k, v = kv.split("=")
        over[k] = json.loads(v)
    return int(a), int(b), over


def tag_of(text: str) -> str:
    """A setting as a folder name."""
    return text.replace("+", "_").replace("=", "")


def evaluate(run: Path, side: int, iters: int, folds: int, field: dict | None = None, methods=None) -> dict:
    """The product's evaluation of ``run`` at (side, iters) and ``field`` (FieldConfig overrides) over its first
    ``folds`` folds -> summary.json."""
    from curate.pipeline import saved_config
    from curate.core import runfolder
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    cfg, _ = saved_config(run)
    ev = cfg.evaluate
    cfg = replace(cfg, evaluate=replace(ev, max_side=side, iters=iters, folds=folds,
                                        methods=methods or ("selection", "random", "fvs", "stride", "all"),
                                        random_seeds=1, field=replace(ev.field, **(field or {}))))
    with runfolder.claimed(run, writes=("evaluate",)):
        res = run_stage(BY_NAME["evaluate"], RunContext(cfg, run))
    print(res.line(), flush=True)
    return json.loads((run / "evaluate" / "summary.json").read_text())


def unit_seconds(run: Path) -> float:
    """Median CPU seconds of one training (its ``metrics.json``'s ``cpu_seconds``: the worker's process time over
    training and scoring; a unit of an older curate: its stage record's wall seconds)."""
    secs = []
    for p in (run / "evaluate").glob("f*/metrics.json"):
        m = json.loads(p.read_text())
        if m.get("copied_from"):
            continue
        secs.append(m["cpu_seconds"] if m.get("cpu_seconds") is not None else
                    json.loads((p.parent / "stage.json").read_text()).get("seconds", 0))
    return float(np.median(secs)) if secs else float("nan")


def diffs(summary: dict, rival: str) -> dict[str, float]:
    """{held-out photo: selection - rival, dB}."""
    m = summary["methods"]
    if rival not in m or "selection" not in m:
        return {}
    other = {r["name"]: r["psnr"] for r in m[rival]["per_view"]}
    return {r["name"]: r["psnr"] - other[r["name"]] for r in m["selection"]["per_view"] if r["name"] in other}


def reread(folder: Path, out: Path, texts: list[str], captures: list[str]) -> list[dict]:
    """The agreement table from saved summaries (``folder/<capture>@<tag>.summary.json``, the first two folds'
    of each setting; CPU seconds from the siblings ``out/<capture>@<tag>``), the decisions read with the
    product's interval after two folds: one look at 95% (``--folds 2``) and the first look of an evaluation that
    adds folds (:func:`curate.evaluate.folds.look_level`)."""
    from curate.core.stats import decision, folds_moderated
    from curate.evaluate.folds import KAPPA_PRIOR, look_level
    from research.interval_study import fold_diffs
    rows = []
    ref = tag_of(texts[0])
    for cap in captures:
        summ = {tag_of(t): json.loads((folder / f"{cap}@{tag_of(t)}.summary.json").read_text()) for t in texts}
        secs = {tag_of(t): unit_seconds(out / f"{cap}@{tag_of(t)}") for t in texts}
        for rival in ("random", "fvs", "stride"):
            d_ref = diffs(summ[ref], rival)
            if not d_ref:
                continue
            for tag, s in summ.items():
                d = diffs(s, rival)
                common = sorted(set(d) & set(d_ref))
                r = float(np.corrcoef([d_ref[k] for k in common], [d[k] for k in common])[0, 1])
                fd = fold_diffs(s, rival)[:2]
                p95 = folds_moderated(fd, 0.95, *KAPPA_PRIOR)
                pad = folds_moderated(fd, look_level(True), *KAPPA_PRIOR)
                rows.append({"capture": cap, "rival": rival, "setting": tag, "views": len(common), "r_vs_ref": r,
                             "mean": float(np.mean([d[k] for k in common])), "cpu_s_per_training": secs[tag],
                             "lo95": p95["lo"], "hi95": p95["hi"], "decision_folds2": decision(p95, 0.3),
                             "decision_first_look": decision(pad, 0.3)})
    print(f"{'capture':11s} {'rival':7s} {'views':>5s} {'r':>5s} {'ref mean':>8s} {'new mean':>8s} {'ratio':>6s} "
          f"{'ref (2 folds, 95%)':>26s} {'new (2 folds, 95%)':>26s} {'CPU s ref -> new':>17s}")
    for cap in captures:
        for rival in ("random", "fvs", "stride"):
            rs = [x for x in rows if x["capture"] == cap and x["rival"] == rival]
            if len(rs) < 2:
                continue
            a, b = rs[0], rs[-1]
            print(f"{cap:11s} {rival:7s} {b['views']:5d} {b['r_vs_ref']:5.2f} {a['mean']:+8.2f} {b['mean']:+8.2f} "
                  f"{b['mean'] / a['mean'] if a['mean'] else float('nan'):6.2f} "
                  f"{a['lo95']:+6.2f}..{a['hi95']:+5.2f} {a['decision_folds2']:>9s}  "
                  f"{b['lo95']:+6.2f}..{b['hi95']:+5.2f} {b['decision_folds2']:>9s} "
                  f"{a['cpu_s_per_training']:7.1f} -> {b['cpu_s_per_training']:5.1f}")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", help="run folders (SfM, occupancy and selection done)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--settings", default="240x800,160x400,160x250", help="SIDExITERS[+field=value...], comma "
                    "list; the first is the reference")
    ap.add_argument("--folds", type=int, default=2)
    ap.add_argument("--reread", type=Path, default=None, help="train nothing: the table from the summaries saved in "
                    "this folder (<capture>@<setting>.summary.json), captures named by the runs' names")
    a = ap.parse_args(argv)
    texts = a.settings.split(",")
    out = Path(a.out)
    if a.reread:
        rows = reread(a.reread, out, texts, [Path(r).name for r in a.runs])
        print(json.dumps({"settings": a.settings, "folds": 2, "rows": rows}))
        return 0
    rows = []
    for run in map(Path, a.runs):
        name = run.name
        summ, secs = {}, {}
        for text in texts:
            side, iters, over = setting(text)
            tag = tag_of(text)
            sib = sibling(run, out / f"{name}@{tag}")
            summ[tag] = evaluate(sib, side, iters, a.folds, over)
            secs[tag] = unit_seconds(sib)
        ref = tag_of(texts[0])
        print(f"\n{name}: {summ[ref]['protocol']['n_folds']} folds, "
              f"{len(summ[ref]['protocol']['holdout'])} held-out photos")
        print(f"{'rival':8s} {'setting':9s} {'mean':>7s} {'interval':>16s} {'decision':>9s} {'r':>6s} "
              f"{'s/train':>8s}")
        for rival in ("random", "fvs", "stride"):
            d_ref = diffs(summ[ref], rival)
            if not d_ref:
                continue
            for tag in summ:
                d = diffs(summ[tag], rival)
                common = sorted(set(d) & set(d_ref))
                r = float(np.corrcoef([d_ref[k] for k in common], [d[k] for k in common])[0, 1]) \
                    if len(common) > 2 else float("nan")
                p = summ[tag]["paired"].get(f"selection-{rival}") or {}
                print(f"{rival:8s} {tag:9s} {p.get('mean', float('nan')):+7.2f} "
                      f"{p.get('lo', float('nan')):+7.2f}..{p.get('hi', float('nan')):+6.2f} "
                      f"{str(p.get('decision')):>9s} {r:6.2f} {secs[tag]:8.1f}")
                rows.append({"capture": name, "rival": rival, "setting": tag, "mean": p.get("mean"),
                             "lo": p.get("lo"), "hi": p.get("hi"), "sd": p.get("sd"), "n": p.get("n"),
                             "decision": p.get("decision"), "r_vs_ref": r, "seconds_per_training": secs[tag],
                             "psnr": {m: v["psnr"] for m, v in summ[tag]["methods"].items()}})
    print(json.dumps({"settings": a.settings, "folds": a.folds, "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
