"""Benchmark the verdict: how decided it is, and in how much time, on real captures (issue 48).

For each run folder (SfM, occupancy and selection done), a sibling ``<out>/<name>`` shares its SfM, occupancy
and selection (hard links, :func:`research.eval_agreement.sibling`) and the product's own evaluation runs there
as ``curate evaluate`` runs it (the run's saved options; the evaluation's own at today's defaults unless
``--keep-saved``), timed on the wall clock. Printed per capture: the folds, the held-out photos, why it stopped,
the wall time, and for each rival the mean difference, its interval, its half-width and what it decides.
``--summarize`` reads finished siblings without training. One JSON line last.

    python -m research.bench.bench_verdict RUN_office_mp4 RUN_office --out /tmp/bench
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path


def run_one(run: Path, out: Path, keep_saved: bool) -> float:
    """The product's evaluation of ``run``'s sibling in ``out``; returns its wall seconds."""
    from curate.pipeline import saved_config
    from curate.core import runfolder
    from curate.core.graph import BY_NAME, RunContext
    from curate.core.runner import run_stage
    from curate.evaluate.config import EvalConfig
    from research.eval_agreement import sibling
    sib = sibling(run, out)
    cfg, _ = saved_config(sib)
    if not keep_saved:
        d = EvalConfig()
        cfg = replace(cfg, evaluate=replace(cfg.evaluate, max_side=d.max_side, iters=d.iters, methods=d.methods,
                                            random_seeds=d.random_seeds, folds=d.folds, minutes=d.minutes))
    t0 = time.perf_counter()
    with runfolder.claimed(sib, writes=("evaluate",)):
        print(run_stage(BY_NAME["evaluate"], RunContext(cfg, sib)).line(), flush=True)
    return time.perf_counter() - t0


def summary(sib: Path, wall: float | None) -> dict:
    s = json.loads((sib / "evaluate" / "summary.json").read_text())
    pr = s["protocol"]
    row = {"capture": sib.name, "n_registered": pr["n_registered"], "exported": pr["exported_budget"],
           "folds": pr["n_folds"], "planned": pr["planned_folds"], "held_out": len(pr["holdout"]),
           "stopped": pr["stopped"], "seconds": pr.get("seconds"), "wall_s": None if wall is None else round(wall, 1),
           "gap_closed": s.get("gap_closed"), "paired": {}}
    for k, p in s["paired"].items():
        row["paired"][k.split("-", 1)[1]] = {"mean": round(p["mean"], 3), "lo": round(p["lo"], 3),
                                             "hi": round(p["hi"], 3), "half": round((p["hi"] - p["lo"]) / 2, 3),
                                             "decision": p["decision"]}
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--keep-saved", action="store_true", help="the run's saved evaluation options, not today's")
    ap.add_argument("--summarize", action="store_true", help="read finished siblings, train nothing")
    a = ap.parse_args(argv)
    rows = []
    for run in map(Path, a.runs):
        sib = a.out / run.name
        wall = None if a.summarize else run_one(run, sib, a.keep_saved)
        r = summary(sib, wall)
        rows.append(r)
        print(f"{r['capture']}: {r['folds']} of {r['planned']} folds, {r['held_out']} held-out photos, "
              f"stopped: {r['stopped']}, {r['seconds']} s; " + "; ".join(
                  f"- {k} {p['mean']:+.2f} [{p['lo']:+.2f}, {p['hi']:+.2f}] ±{p['half']:.2f} {p['decision']}"
                  for k, p in r["paired"].items()), flush=True)
    print(json.dumps({"rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
