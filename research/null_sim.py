"""The verdict's false calls where nothing differs: the evaluation's looks and plan, simulated (issue 59, item 2).

Each simulated capture has ``photos`` held-out photos in capture order, split into folds as the evaluation splits
them (every 14th photo from each offset, in :func:`curate.evaluate.folds.fold_order`), and per photo a difference
selection - rival whose mean over the capture is exactly 0 (nothing differs):

* a smooth part along the capture (an AR(1) walk of correlation ``rho`` per photo, sd ``sigma_smooth``: the ends
  of a walk, its turns; neighbouring photos fall in different folds, so the folds' means agree *more* than
  independent views would: a design effect below 1),
* an independent part per photo (sd ``sigma``),
* a fold effect shared by a fold's views (sd ``tau``: a training that converged a little better, a lucky random
  draw), which raises the design effect above 1,

then centred on the capture's mean so that the true difference is 0. The procedure is the product's
(:class:`curate.evaluate.stage.Planner`'s looks with :func:`curate.core.stats.folds_moderated` at
:data:`curate.evaluate.folds.KAPPA_PRIOR`): a look after 2 folds; undecided, the folds the projection
(:func:`curate.evaluate.folds.folds_to_decide`) says decide it, if the time holds them (``--time-folds``: the folds
the minutes given hold); undecided there, a last look at the folds the projection then asks for at 80% power
(:func:`curate.evaluate.folds.next_look`), if the time holds them (until issue 59's item 3, at the end of the time).
A *false call* is "ahead" or "behind" at any look ("resolved", an interval that holds 0 at most ``--resolution``
wide on each side, is no call). Printed per setting: the design effect the setting has (measured over the
simulations), the false-call rate and its 95% binomial upper bound; one JSON line last.

    python -m research.null_sim --reps 2000                  # the product's
    python -m research.null_sim --reps 2000 --interval old   # before issue 59
"""

from __future__ import annotations

import argparse
import json
import math
import sys

import numpy as np


def capture(rng, photos: int, sigma: float, sigma_smooth: float, rho: float, tau: float, every: int = 14):
    """Per fold (in the evaluation's order) the per-view differences of one null capture."""
    from curate.evaluate.folds import fold_order
    from scipy.signal import lfilter
    e = rng.normal(0, sigma, photos)
    burn = 300
    w = rng.normal(0, sigma_smooth, photos + burn)
    s = lfilter([math.sqrt(1 - rho * rho)], [1, -rho], w)[burn:] if rho > 0 else w[burn:]
    x = e + s
    folds = []
    for o in fold_order(every, photos):
        folds.append(x[o::every] + rng.normal(0, tau))
    allx = np.concatenate(folds)
    m = float(allx.mean())
    return [f - m for f in folds]


def procedure(diffs, margin: float, time_folds: int, prior, level: float, resolution: float = 0.0) -> tuple[str, int]:
    """The product's looks on ``diffs`` (one rival): (the decision it ends with, the folds it used)."""
    from curate.core.stats import decision, folds_moderated
    from curate.evaluate.folds import FIRST_LOOK, LOOKS, next_look
    F_max = min(len(diffs), time_folds)
    F = min(FIRST_LOOK, F_max)
    looks = 0
    while True:
        p = folds_moderated(diffs[:F], level, kappa0=prior[0], nu0=prior[1])
        looks += 1
        d = decision(p, margin, resolution)
        if d != "undecided" or F >= F_max or looks >= LOOKS:
            return d, F
        g = next_look(p, margin, len(diffs), resolution, last=looks == LOOKS - 1, prior=prior)
        if g is None or g > F_max:
            return d, F              # the time given would not decide it: stop, say what it needs
        F = g                        # each look at the folds the projection asks for (issue 59, item 3)


def procedure_old(diffs, margin: float, time_folds: int) -> tuple[str, int]:
    """The evaluation before issue 59 on ``diffs``: the folds alone (:func:`curate.core.stats.folds_paired`, t on
    F - 1), a look after 4 folds and one at the end of the time (each at 97.5% when there are two, else 95%)."""
    from curate.core.stats import decision, folds_paired
    F_max = min(len(diffs), time_folds)
    looks = [F_max] if F_max <= 4 else [4, F_max]
    level = 0.95 if len(looks) == 1 else 1 - 0.05 / 2
    for F in looks:
        d = decision(folds_paired(diffs[:F], level), margin)
        if d != "undecided":
            return d, F
    return d, F_max


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--prior", default=None, help="KAPPA0,NU0 (default: the product's)")
    ap.add_argument("--margin", type=float, default=0.3)
    ap.add_argument("--resolution", type=float, default=None, help="stop a rival whose interval is at most this "
                    "wide on each side (default: the product's EvalConfig.resolution_db; 0: never)")
    ap.add_argument("--interval", choices=("new", "old"), default="new", help="new: the product's looks and "
                    "prior; old: before issue 59 (the folds alone, looks after 4 folds and at the end)")
    a = ap.parse_args(argv)
    from curate.core.stats import folds_moderated
    from curate.evaluate.folds import KAPPA_PRIOR, look_level
    prior = tuple(float(x) for x in a.prior.split(",")) if a.prior else KAPPA_PRIOR
    from curate.evaluate.config import EvalConfig
    res = EvalConfig().resolution_db if a.resolution is None else a.resolution
    level = look_level(True)
    rng = np.random.default_rng(a.seed)
    settings = []
    for photos in (70, 373):
        for sigma, smooth, rho in ((2.8, 0.0, 0.0), (1.5, 2.5, 0.9), (0.5, 2.8, 0.97)):
            for tau in (0.0, 0.1, 0.3, 0.6):
                for tf in (4, 8, 14):
                    settings.append({"photos": photos, "sigma": sigma, "sigma_smooth": smooth, "rho": rho,
                                     "tau": tau, "time_folds": tf})
    rows = []
    print(f"interval {a.interval}" + (f", prior {prior}, level {level}" if a.interval == "new" else ""))
    for st in settings:
        calls, kap, used = 0, [], []
        for _ in range(a.reps):
            diffs = capture(rng, st["photos"], st["sigma"], st["sigma_smooth"], st["rho"], st["tau"])
            k = folds_moderated(diffs, nu0=0)["kappa_folds"]
            if k is not None:
                kap.append(k)
            d, F = (procedure(diffs, a.margin, st["time_folds"], prior, level, res) if a.interval == "new" else
                    procedure_old(diffs, a.margin, st["time_folds"]))
            calls += d in ("ahead", "behind")
            used.append(F)
        rate = calls / a.reps
        hi = rate + 1.96 * math.sqrt(max(rate * (1 - rate), 1e-12) / a.reps)
        row = {**st, "kappa": float(np.median(kap)), "false_calls": rate, "upper95": hi,
               "mean_folds": float(np.mean(used))}
        rows.append(row)
        print(f"photos {st['photos']:3d} sd {st['sigma']:.1f} smooth {st['sigma_smooth']:.1f} rho {st['rho']:.2f} "
              f"tau {st['tau']:.1f} time {st['time_folds']:2d} folds: kappa {row['kappa']:5.2f}  false calls "
              f"{rate:.3f} (<= {hi:.3f})  folds used {row['mean_folds']:.1f}", flush=True)
    worst = max(rows, key=lambda r: r["false_calls"])
    print(json.dumps({"interval": a.interval, "prior": prior if a.interval == "new" else None, "level": level,
                      "resolution": res if a.interval == "new" else None,
                      "reps": a.reps, "worst": worst,
                      "rows": rows}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
