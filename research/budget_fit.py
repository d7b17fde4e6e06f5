"""Fit and validate the ``--budget auto`` predictor on the harness's measured units (issue 25).

Reads harness output folders (``python3 -m research.harness ... --out OUT``): for every
scene, the pool's spacing curve (:mod:`curate.select.spacing`) and, for every trained unit
of fold 0, its held-out PSNR on and off the path against the all-frames unit. Then

* fits the loss model of :mod:`curate.select.auto_budget` (loss = PSNR(all) - PSNR(k) of
  the default selection, in dB, as a function of the spacing at k), on every scene and
  leaving each scene out in turn;
* for each scene and part, compares the budget the left-out fit predicts for a tolerance
  with the budget the measured curve needs (linear interpolation between measured budgets).

Prints one JSON line (``{"points": ..., "fit": ..., "validation": ...}``); ``--json F`` writes
it to F too. Example::

    python3 -m research.budget_fit --out /tmp/h25 --blocks /tmp/hb=6:8:4 --json docs/evidence/budget_auto.json
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np


def pool_spacing(c: np.ndarray, a: np.ndarray, depths: np.ndarray, chunk: int = 1024) -> float:
    """rho_nn: the mean over the views ``c``, ``a`` [K, 3] of the view distance to their nearest
    other view, divided by their ``depths`` [K] (how far an unseen view on the same path is from
    the pool when every frame is kept). 0 for fewer than 2 views. Memory [chunk, K]."""
    from curate.select.medoids import view_distance
    K = len(c)
    if K < 2:
        return 0.0
    allk = np.arange(K)
    out = np.empty(K)
    for s in range(0, K, chunk):
        rows = allk[s:s + chunk]
        d = view_distance(c, a, rows, allk)                              # [r, K]
        d[np.arange(len(rows)), rows] = np.inf
        out[rows] = d.min(axis=1)
    return float(np.mean(out / np.asarray(depths, np.float64)))


def subset_spacing(c: np.ndarray, a: np.ndarray, depths: np.ndarray, subset, chunk: int = 2048) -> float:
    """rho(S) (:mod:`curate.select.spacing`) for the pool views ``c``, ``a`` [K, 3] and the pool
    indices ``subset``; memory [chunk, |S|]."""
    from curate.select.medoids import view_distance
    K = len(c)
    S = np.asarray(list(subset), np.int64)
    if K == 0 or len(S) == 0:
        return float("inf") if K else 0.0
    allk = np.arange(K)
    near = np.empty(K)
    for s in range(0, K, chunk):
        near[s:s + chunk] = view_distance(c, a, allk[s:s + chunk], S).min(axis=1)
    return float(np.mean(near / np.asarray(depths, np.float64)))


def pool_of(run: Path, pool: list[int]):
    """(pool cameras, kind, c, a, depths) of a run folder's ``pool``, as ``--budget auto`` sees it."""
    from curate.core.run import load_node_grid
    from curate.select.auto_budget import pool_views
    from curate.select.config import EnergyConfig
    from curate.select.methods import capture_kind
    from curate.select.visibility import build_pair_index
    from curate.sfm.io import load_sfm
    pc = load_sfm(run).cameras[pool]
    nodes = load_node_grid(run).nodes()
    return (pc, capture_kind(pc)[0], *pool_views(pc, nodes, build_pair_index(pc, nodes, EnergyConfig().bins)))


def harness_split(run: Path, every: int = 14):
    """(pool [n], held out [t]) of fold 0 of a harness scene folder (every ``every``-th camera held out,
    as the harness's default protocol; earlier harness folders recorded it in occupancy/split.json)."""
    from curate.core.stats import holdout_split
    from curate.sfm.io import load_sfm
    old = run / "occupancy" / "split.json"
    if old.is_file():
        sp = json.loads(old.read_text())
        return np.asarray(sp["pool"]), np.asarray(sp["holdout"])
    return holdout_split(len(load_sfm(run).cameras), every)


def scene_points(run: Path, blocks: tuple[int, int, int] | None = None) -> list[dict]:
    """Measured points of one harness scene folder: one per trained unit of fold 0 (and 'all')."""
    from curate.select.spacing import spacing_curve
    from curate.sfm.io import load_sfm
    sfm = load_sfm(run)
    if blocks:
        from research.harness import holdout_blocks
        pool, hold = (x.tolist() for x in holdout_blocks(len(sfm.cameras), *blocks, 0))
    else:
        pool, hold = (x.tolist() for x in harness_split(run))
    _, kind, c, a, depths = pool_of(run, pool)
    _, rho = spacing_curve(c, a, depths)
    rho_nn = pool_spacing(c, a, depths)
    rel = {g: i for i, g in enumerate(pool)}
    units = {}
    for m in sorted((run / "evaluate").glob("*/metrics.json")):
        name = m.parent.name
        if name.startswith("q_") and "_o" in name.rsplit("_b", 1)[-1]:
            continue                                          # another fold's unit
        if name != "all" and not name.startswith("q_"):
            continue
        r = json.loads(m.read_text())
        pv = np.array([v["psnr"] for v in r["per_view"]])
        units[name] = (r, pv)
    if "all" not in units:
        return []
    all_pv = units["all"][1]
    nh = len(hold)
    out = []
    for name, (r, pv) in units.items():
        if name == "all" or len(pv) != len(all_pv):
            continue
        sub = [rel[g] for g in r["subset"] if g in rel]
        k = len(sub)
        method = name[2:].rsplit("_b", 1)[0]
        row = {"scene": run.name, "kind": kind, "unit": name, "method": method, "k": k, "pool": len(pool),
               "rho_fp": float(rho[k - 1]), "rho_sel": subset_spacing(c, a, depths, sub), "rho_nn": rho_nn,
               "loss_on": float(all_pv[:nh].mean() - pv[:nh].mean()),
               "psnr_on": float(pv[:nh].mean()), "all_on": float(all_pv[:nh].mean())}
        if len(pv) > nh:
            row.update(loss_off=float(all_pv[nh:].mean() - pv[nh:].mean()),
                       psnr_off=float(pv[nh:].mean()), all_off=float(all_pv[nh:].mean()))
        out.append(row)
    out.append({"scene": run.name, "kind": kind, "curve": rho.tolist(), "rho_nn": rho_nn, "pool": len(pool)})
    return out


MIN_LOSS = 0.05
"""Points whose measured loss is below this (dB) carry no information on a log scale (noise): left
out of the power-law fit."""


def fit_alpha(rows: list[dict], part: str = "on") -> float:
    """Least squares through the origin of loss_<part> on rho_sel over ``rows`` (the linear model)."""
    x = np.array([r["rho_sel"] for r in rows])
    y = np.array([r[f"loss_{part}"] for r in rows])
    return float(x @ y / (x @ x)) if len(x) and x @ x > 0 else float("nan")


def fit_power(rows: list[dict], part: str = "on") -> tuple[float, float]:
    """(alpha, p) of loss = alpha * rho ** p, least squares in log-log over the ``rows`` whose
    loss is at least MIN_LOSS; (nan, nan) with fewer than 3 such rows."""
    r = [x for x in rows if x.get(f"loss_{part}", 0.0) >= MIN_LOSS and x["rho_sel"] > 0]
    if len(r) < 3:
        return float("nan"), float("nan")
    lx = np.log([x["rho_sel"] for x in r])
    ly = np.log([x[f"loss_{part}"] for x in r])
    p, la = np.polyfit(lx, ly, 1)
    return float(np.exp(la)), float(p)


def measured_budget(rows: list[dict], tol: float, part: str = "on") -> tuple[float | None, str]:
    """The smallest budget (images) at which the measured loss of ``rows`` (one method, one scene,
    several budgets) is within ``tol`` dB, interpolated linearly between measured budgets; (None,
    '> K') when no measured budget reaches it, (k_min, '<= k_min') when the smallest does."""
    pts = sorted((r["k"], r[f"loss_{part}"]) for r in rows if f"loss_{part}" in r)
    if not pts:
        return None, "-"
    if pts[0][1] <= tol:
        return float(pts[0][0]), f"<= {pts[0][0]}"
    for (k0, l0), (k1, l1) in zip(pts, pts[1:]):
        if l1 <= tol:
            k = k0 + (l0 - tol) / (l0 - l1) * (k1 - k0)
            return float(k), f"{k:.0f}"
    return None, f"> {pts[-1][0]}"


def measured_loss_at(rows: list[dict], k: int | None, part: str = "on") -> float | None:
    """The measured loss of ``rows`` (one method, one scene) at budget ``k``, interpolated linearly
    between measured budgets; None outside the measured range."""
    pts = sorted((r["k"], r[f"loss_{part}"]) for r in rows if f"loss_{part}" in r)
    if k is None or not pts or not pts[0][0] <= k <= pts[-1][0]:
        return None
    return float(np.interp(k, [x for x, _ in pts], [y for _, y in pts]))


def predicted_budget(curve: list[float], alpha: float, tol: float, power: float = 1.0) -> int:
    """The smallest k in [2, K - 1] with alpha * rho(k) ** power <= tol (K - 1 when none), chosen as
    ``--budget auto`` chooses (:func:`curate.select.auto_budget.fewest_within`)."""
    from curate.select.auto_budget import fewest_within
    rho = np.asarray(curve)
    k = fewest_within(alpha * rho ** power, tol)
    return len(rho) - 1 if k is None else k


def analyse(pts: list[dict], tols=(0.3, 0.5, 1.0)) -> dict:
    """Both loss models (linear: alpha * rho; power: alpha * rho ** p) fitted per capture kind on
    every scene and leaving each scene out; the validation table (predicted and measured budgets)
    and the left-out error of the predicted loss of every measured subset."""
    units = [r for r in pts if "unit" in r]
    curves = {r["scene"]: r for r in pts if "curve" in r}
    fit = {}
    for kind in ("walk", "object"):
        rows = [r for r in units if r["kind"] == kind]
        if rows:
            fit[kind] = {"linear": fit_alpha(rows), "power": fit_power(rows)}
    val, loso, err = [], {}, {"linear": [], "power": []}
    for scene, cv in sorted(curves.items()):
        kind = cv["kind"]
        rows = [r for r in units if r["kind"] == kind and r["scene"] != scene]
        models = {"linear": (fit_alpha(rows), 1.0) if rows else (float("nan"), 1.0),
                  "power": fit_power(rows) if rows else (float("nan"), float("nan"))}
        loso[scene] = models
        mine = [r for r in units if r["scene"] == scene]
        default = [r for r in mine if r["method"].startswith("default")]
        for name, (a, p) in models.items():
            if np.isfinite(a):
                for r in mine:
                    r[f"pred_{name}"] = a * r["rho_sel"] ** p
                    err[name].append({"scene": scene, "kind": kind, "loss": r["loss_on"], "pred": r[f"pred_{name}"]})
        for tol in tols:
            for part in ("on", "off"):
                if not any(f"loss_{part}" in r for r in default):
                    continue
                kb, txt = measured_budget(default, tol, part)
                row = {"scene": scene, "kind": kind, "part": part, "tol": tol, "pool": cv["pool"],
                       "measured": kb, "measured_text": txt, "measured_ks": sorted(r["k"] for r in default)}
                for name, (a, p) in models.items():
                    kp = predicted_budget(cv["curve"], a, tol, p) if np.isfinite(a) else None
                    row[f"predicted_{name}"] = kp
                    row[f"loss_at_predicted_{name}"] = measured_loss_at(default, kp, part)
                val.append(row)

    def summary(e, kind, hi=np.inf):
        d = [x["pred"] - x["loss"] for x in e if x["kind"] == kind and x["loss"] < hi]
        return {"n": len(d), "rmse": float(np.sqrt(np.mean(np.square(d)))) if d else None,
                "mean": float(np.mean(d)) if d else None}
    errs = {m: {k: {"all": summary(e, k), "loss < 2 dB": summary(e, k, 2.0)} for k in fit} for m, e in err.items()}
    # the rule: per kind, the model whose left-out error on losses below 2 dB (the range a tolerance
    # lives in) is smaller; its constants fitted on every scene of that kind go to the product
    product = {}
    for k in fit:
        r = {m: (errs[m][k]["loss < 2 dB"]["rmse"] or np.inf) for m in ("linear", "power")}
        m = min(r, key=r.get)
        a, p = (fit[k]["linear"], 1.0) if m == "linear" else fit[k]["power"]
        product[k] = {"model": m, "alpha": round(a, 2), "p": round(p, 2)}
    return {"fit": fit, "product": product, "loso": loso, "validation": val,
            "loss_error_on": errs}


def predict_run(run: Path, at: list[int], tols=(0.3, 0.5, 1.0)) -> dict:
    """What ``--budget auto`` predicts for the pool of run folder ``run`` (its split.json), with the
    product's constants (a scene that took no part in the fit is a confirmation). Where ``run`` is a
    harness scene folder with trained units of the default method and 'all', the measured figures
    stand beside it (on-path views): ``measured_loss_at`` the budgets measured, and per tolerance
    the measured budget and the measured loss at the predicted one."""
    from curate.select.auto_budget import LOSS_MODEL, predicted_loss
    from curate.select.spacing import spacing_curve
    pc, kind, c, a, depths = pool_of(run, harness_split(run)[0].tolist())
    _, rho = spacing_curve(c, a, depths)
    loss = predicted_loss(rho, kind)
    alpha, power = LOSS_MODEL[kind]
    budgets = {t: predicted_budget(rho, alpha, t, power) for t in tols}      # as choose_budget, one curve
    default = ([r for r in scene_points(run) if "unit" in r and r["method"].startswith("default")]
               if (run / "evaluate").is_dir() else [])
    ks = sorted({r["k"] for r in default}) + list(at)
    out = {"run": str(run), "pool": len(pc), "kind": kind,
           "loss_at": {k: round(float(loss[k - 1]), 3) for k in ks if 1 <= k <= len(pc)},
           "budget_at": budgets}
    if default:
        out["measured_loss_at"] = {r["k"]: round(r["loss_on"], 3) for r in sorted(default, key=lambda r: r["k"])}
        out["measured"] = {t: {"predicted": kp, "measured": measured_budget(default, t)[1],
                               "loss_at_predicted": (None if (x := measured_loss_at(default, kp)) is None
                                                     else round(x, 3))}
                           for t, kp in budgets.items()}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", action="append", default=[], help="a harness --out folder (repeatable)")
    ap.add_argument("--blocks", action="append", default=[],
                    help="OUT=N:L:G: a harness folder run with --holdout-blocks N:L:G")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--predict", type=Path, action="append", default=[],
                    help="a run folder: print the product's prediction for its pool (loss at --at budgets, "
                         "budget at each tolerance) and stop")
    ap.add_argument("--at", default="", help="--predict: budgets (counts, comma separated)")
    args = ap.parse_args(argv)
    if args.predict:
        for run in args.predict:
            print(json.dumps(predict_run(run, [int(x) for x in args.at.split(",") if x])))
        return 0
    pts = []
    folders = [(Path(o), None) for o in args.out]
    for b in args.blocks:
        o, spec = b.split("=")
        folders.append((Path(o), tuple(int(x) for x in spec.split(":"))))
    for o, blk in folders:
        for run in sorted(p for p in o.iterdir() if (p / "sfm").is_dir() and (p / "evaluate").is_dir()):
            got = scene_points(run, blk)
            for r in got:
                if blk:
                    r["scene"] = f"{r['scene']}-blocks"
            pts += got
            print(f"{run}: {sum('unit' in r for r in got)} units", file=sys.stderr)
    res = {"points": pts, **analyse(pts)}
    line = json.dumps(res)
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(line + "\n")
    print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
