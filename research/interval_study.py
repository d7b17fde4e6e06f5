"""How wide must the verdict's interval be after two, three, four folds? (issue 59, item 2)

Reads evaluated run folders that trained many hold-out folds (``RUN/evaluate/summary.json``: per held-out photo,
its fold and its PSNR under the selection and each rival) and, per capture and rival:

* the *design effect* ``kappa`` over all folds: the cluster-robust variance of the pooled mean
  (:func:`curate.core.stats.folds_paired`) over the views' within-fold variance / N, with F - 1 degrees of
  freedom; what the prior of :func:`curate.core.stats.folds_moderated` is fitted to;
* the prior ``(kappa0, nu0)`` fitted by maximum likelihood (``kappa_hat / kappa0 ~ F(F - 1, nu0)``: a scaled
  inverse chi-square prior, as a moderated variance's) on every capture, and on every capture but one;
* coverage: over many draws of k folds (k = 2, 3, 4, 7), how often the interval of those k folds holds the mean
  of all folds (the cross-validation estimate the evaluation converges to), the old interval (the folds alone,
  t on k - 1) and the new (with the product's prior, ``curate.evaluate.folds.KAPPA_PRIOR``), at the level the
  product uses;
* the verdicts after the first 2, 3, 4, 7 folds in the product's order, old beside new.

    python -m research.interval_study RUN... --json docs/evidence/interval_study.json

No training: the runs' trainings are read. ``--prior KAPPA0,NU0`` evaluates another prior than the product's;
``--prior fitted``: each capture's figures with the prior fitted on the other captures (chosen on part, checked
on the rest).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import sys
from pathlib import Path

import numpy as np

RIVALS = ("random", "fvs", "stride")


def fold_diffs(summary: dict, rival: str) -> list[np.ndarray]:
    """Per fold, in the order trained, the per-view differences selection - ``rival`` (dB)."""
    m = summary["methods"]
    if rival not in m or "selection" not in m:
        return []
    sel = {r["name"]: r for r in m["selection"]["per_view"]}
    oth = {r["name"]: r for r in m[rival]["per_view"]}
    out = []
    for f in summary["protocol"]["folds"]:
        names = [sel_name for sel_name, r in sel.items() if r["fold"] == f["offset"] and sel_name in oth]
        if names:
            out.append(np.array([sel[k]["psnr"] - oth[k]["psnr"] for k in names]))
    return out


def kappa_hat(diffs: list[np.ndarray]) -> tuple[float, int] | None:
    """(design effect over all folds, its degrees of freedom F - 1); None below two folds or without spread."""
    from curate.core.stats import folds_moderated
    if len(diffs) < 2:
        return None
    k = folds_moderated(diffs, nu0=0.0)["kappa_folds"]
    return (k, len(diffs) - 1) if k is not None and k > 0 else None


def fit_prior(k: list[float], d: list[int]) -> tuple[float, float]:
    """ML fit of (kappa0, nu0): ``k_i / kappa0 ~ F(d_i, nu0)``."""
    from scipy.optimize import minimize
    from scipy.stats import f as fdist
    k, d = np.asarray(k, float), np.asarray(d, float)

    def nll(p):
        k0, nu = math.exp(p[0]), math.exp(p[1])
        return -float(np.sum(fdist.logpdf(k / k0, d, nu) - math.log(k0)))
    best = min((minimize(nll, [math.log(max(np.median(k), 1e-3)), math.log(nu)], method="Nelder-Mead")
                for nu in (2.0, 10.0, 50.0)), key=lambda r: r.fun)
    return float(math.exp(best.x[0])), float(min(math.exp(best.x[1]), 1e4))


def upper(prior: tuple[float, float], q: float) -> tuple[float, float]:
    """The prior moved up to the ``q``-quantile of the design effect it describes (scaled inverse chi-square):
    a conservative kappa0, the same nu0."""
    from scipy.stats import chi2
    k0, nu = prior
    return k0 * nu / float(chi2.ppf(1 - q, nu)), nu


def interval(diffs, level, prior):
    from curate.core.stats import folds_moderated, folds_paired
    if prior is None:
        return folds_paired(diffs, level)
    return folds_moderated(diffs, level, kappa0=prior[0], nu0=prior[1])


def coverage(diffs, truth, ks, level, prior, rng, draws=200) -> dict:
    """{k: [hits, trials, mean half-width]} over draws of k of the folds."""
    out = {}
    F = len(diffs)
    for k in ks:
        if k >= F:
            continue
        combos = list(itertools.combinations(range(F), k))
        if len(combos) > draws:
            combos = [combos[i] for i in rng.choice(len(combos), draws, replace=False)]
        hits, halves = 0, []
        for c in combos:
            p = interval([diffs[i] for i in c], level, prior)
            hits += bool(p["lo"] <= truth <= p["hi"])
            halves.append((p["hi"] - p["lo"]) / 2)
        out[k] = [hits, len(combos), float(np.median(halves))]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", nargs="+", type=Path)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--level", type=float, default=None, help="each look's level (default: the product's)")
    ap.add_argument("--prior", default=None, help="KAPPA0,NU0, or 'fitted' (leave one capture out), instead of "
                    "the product's")
    ap.add_argument("--ks", default="2,3,4,7")
    ap.add_argument("--margin", type=float, default=0.3)
    ap.add_argument("--upper", type=float, default=None, help="the prior's kappa0 at this quantile of its fitted "
                    "distribution (a conservative prior) instead of its scale")
    a = ap.parse_args(argv)
    from curate.core.stats import decision
    from curate.evaluate.folds import look_level
    level = a.level or look_level(True)
    ks = [int(x) for x in a.ks.split(",")]
    caps = {}
    for run in a.runs:
        s = json.loads((run / "evaluate" / "summary.json").read_text())
        caps[run.name] = {r: fold_diffs(s, r) for r in RIVALS}
    rows = []
    for cap, by in caps.items():
        for r, diffs in by.items():
            kh = kappa_hat(diffs)
            if kh:
                rows.append({"capture": cap, "rival": r, "folds": len(diffs), "views": int(sum(map(len, diffs))),
                             "kappa": kh[0], "dof": kh[1],
                             "sd_within": interval(diffs, 0.95, (1.0, 1.0))["sd_within"]})
    print(f"{'capture':12s} {'rival':7s} {'folds':>5s} {'views':>5s} {'kappa':>6s} {'sd_w':>5s}")
    for r in rows:
        print(f"{r['capture']:12s} {r['rival']:7s} {r['folds']:5d} {r['views']:5d} {r['kappa']:6.2f} "
              f"{r['sd_within']:5.2f}")
    fitted = fit_prior([r["kappa"] for r in rows], [r["dof"] for r in rows])
    if a.upper:
        fitted = upper(fitted, a.upper)
    print(f"prior fitted on all: kappa0 {fitted[0]:.3f}, nu0 {fitted[1]:.1f}")
    from curate.evaluate.folds import KAPPA_PRIOR
    given = (None if a.prior == "fitted" else tuple(float(x) for x in a.prior.split(",")) if a.prior
             else tuple(KAPPA_PRIOR))
    rng = np.random.default_rng(0)
    cov_rows, verdicts, loo = [], [], {}
    for cap, by in caps.items():
        others = [r for r in rows if r["capture"] != cap]
        prior = given or (fit_prior([r["kappa"] for r in others], [r["dof"] for r in others]) if len(others) > 2
                          else fitted)
        if a.upper and not given and len(others) > 2:
            prior = upper(prior, a.upper)
        loo[cap] = prior
        for r, diffs in by.items():
            if len(diffs) < 2:
                continue
            truth = float(np.mean(np.concatenate(diffs)))
            for name, pr in (("old", None), ("new", prior)):
                cov_rows.append({"capture": cap, "rival": r, "interval": name, "truth": truth,
                                 "coverage": coverage(diffs, truth, ks, level, pr, rng)})
                for k in ks + [len(diffs)]:
                    if k > len(diffs):
                        continue
                    p = interval(diffs[:k], level, pr)
                    verdicts.append({"capture": cap, "rival": r, "interval": name, "folds": k, "mean": p["mean"],
                                     "lo": p["lo"], "hi": p["hi"], "decision": decision(p, a.margin)})
    print("\npriors used (fitted: on the other captures): "
          + ", ".join(f"{c} ({k0:.2f}, {nu:.1f})" for c, (k0, nu) in loo.items()))
    print("\ncoverage of the all-fold mean (hits / draws, median half-width), level", level)
    for k in ks:
        for name in ("old", "new"):
            h = sum(c["coverage"][k][0] for c in cov_rows if c["interval"] == name and k in c["coverage"])
            t = sum(c["coverage"][k][1] for c in cov_rows if c["interval"] == name and k in c["coverage"])
            if t:
                print(f"  {k} folds, {name}: {h}/{t} = {h / t:.3f}")
    print("\nverdicts in the product's fold order (old | new)")
    for cap, by in caps.items():
        for r in by:
            vs = [v for v in verdicts if v["capture"] == cap and v["rival"] == r]
            if not vs:
                continue
            line = []
            for k in sorted({v["folds"] for v in vs}):
                o = next(v for v in vs if v["folds"] == k and v["interval"] == "old")
                n = next(v for v in vs if v["folds"] == k and v["interval"] == "new")
                line.append(f"{k}: {o['mean']:+.2f} [{o['lo']:+.2f},{o['hi']:+.2f}] {o['decision'][:4]} | "
                            f"[{n['lo']:+.2f},{n['hi']:+.2f}] {n['decision'][:4]}")
            print(f"  {cap:11s} {r:6s} " + "; ".join(line))
    out = {"level": level, "prior_all": fitted, "prior_used": loo, "kappas": rows, "coverage": cov_rows,
           "verdicts": verdicts}
    if a.json:
        a.json.write_text(json.dumps(out, indent=1, default=float))
    print(json.dumps({"prior_all": fitted, "prior_used": loo, "level": level,
                      "coverage": {name: {k: [sum(c["coverage"][k][0] for c in cov_rows if c["interval"] == name
                                                  and k in c["coverage"]),
                                              sum(c["coverage"][k][1] for c in cov_rows if c["interval"] == name
                                                  and k in c["coverage"])] for k in ks}
                                   for name in ("old", "new")}}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
