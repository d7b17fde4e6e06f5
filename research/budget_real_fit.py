"""Fit and validate ``--budget auto`` on real captures (issue 34), from :mod:`research.budget_real`'s curves.

For each capture (``<out>/<scene>/curve.json``): the measured loss of the default selection against
all photos at each budget (mean over the held-out photos, pooled over folds), and the spacing
rho(k) of the pool (the quantity the law reads). Then, per kind of capture (walk, object):

* each capture's own alpha (the law's shape, ``loss = alpha * rho ** p`` with the product's p;
  geometric mean of loss / rho ** p over its points losing at least 0.05 dB);
* leaving each capture out: alpha from the captures of its kind of *other scenes* (the highest,
  as the product takes it, and their range; office.mp4 and the office walk are one scene; where
  no other real scene of the kind exists, as for walks, the law fitted on the rendered walks,
  which never saw these captures), the
  budget it predicts for each tolerance on the capture's own curve, the budget measured for it
  (interpolated in log k between measured budgets) and the loss measured at the predicted budget;
* the budget check (:mod:`curate.evaluate.check`) as the product runs it, emulated on the measured
  curve: the law's predicted budget k0 on the evaluation's pool, the losses at k0 / 2, k0 and 2 k0
  (interpolated in log k between measured budgets), fitted and extrapolated; its advice against
  the measured budget.

Prints one JSON line; ``--json F`` writes it too, ``--markdown`` prints the tables.

    python3 -m research.budget_real_fit --out /work/runs/breal --json docs/evidence/budget_real.json --markdown
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

MIN_LOSS = 0.05
TOLS = (0.3, 0.5, 1.0)
SAME_SCENE = {"office_mp4": "office"}
"""Captures of one scene: never used to predict each other."""


def render_alpha() -> dict:
    """The walk law fitted on rendered walks (docs/evidence/budget_auto.json): kind -> (alpha, (low,
    high)) with the range over its fits leaving one rendered walk out; the prediction for a real walk
    when no other real walk scene exists."""
    ev = json.loads((Path(__file__).resolve().parents[1] / "docs" / "evidence" / "budget_auto.json").read_text())
    w = [v["power"][0] for k, v in ev["loso"].items() if k.startswith("walk") or k.startswith("office")]
    return {"walk": (ev["product"]["walk"]["alpha"], (min(w), max(w)))}


def load(out: Path) -> list[dict]:
    """Per capture: kind, n, curve (of fold 0's pool), points [(k, rho, loss, n_views)] pooled over folds."""
    caps = []
    for f in sorted(out.glob("*/curve.json")):
        rec = json.loads(f.read_text())
        by_k: dict[int, list] = {}
        for fold in rec["folds"]:
            allv = np.asarray(fold["all"])
            for p in fold["points"]:
                by_k.setdefault(p["k"], []).append((np.asarray(p["psnr"]), allv, p["rho"]))
        pts = []
        for k, rows in sorted(by_k.items()):
            d = np.concatenate([a - s for s, a, _ in rows])
            pts.append({"k": k, "rho": float(np.mean([r for *_, r in rows])), "loss": float(d.mean()),
                        "sd": float(d.std(ddof=1)) if len(d) > 1 else 0.0, "views": int(len(d))})
        f0 = rec["folds"][0]
        caps.append({"scene": rec["scene"], "kind": rec["kind"], "n": rec["n"], "pool": len(f0["pool"]),
                     "curve": f0["curve"], "points": pts})
    return caps


def capture_alpha(cap: dict, p: float) -> float | None:
    use = [x for x in cap["points"] if x["loss"] >= MIN_LOSS and x["rho"] > 0]
    if not use:
        return None
    return float(np.exp(np.mean([np.log(x["loss"]) - p * np.log(x["rho"]) for x in use])))


def measured_budget(points: list[dict], tol: float) -> tuple[float | None, str]:
    """The budget where the measured loss crosses ``tol`` (log-k interpolation); text for the table."""
    pts = sorted((x["k"], x["loss"]) for x in points)
    if pts[0][1] <= tol:
        return float(pts[0][0]), f"<= {pts[0][0]}"
    for (k0, l0), (k1, l1) in zip(pts, pts[1:]):
        if l1 <= tol:
            f = (l0 - tol) / (l0 - l1)
            k = float(np.exp(np.log(k0) + f * (np.log(k1) - np.log(k0))))
            return k, f"{k:.0f}"
    return None, f"> {pts[-1][0]}"


def loss_at(points: list[dict], k: float) -> float | None:
    pts = sorted((x["k"], x["loss"]) for x in points)
    if not pts[0][0] <= k <= pts[-1][0]:
        return None
    return float(np.interp(np.log(k), np.log([a for a, _ in pts]), [b for _, b in pts]))


def predict(curve, alpha: float, p: float, tol: float) -> int:
    from curate.select.auto_budget import fewest_within
    rho = np.asarray(curve)
    k = fewest_within(alpha * rho ** p, tol)
    return len(rho) - 1 if k is None else k


def check_emulated(cap: dict, alpha_law: float, p: float, tol: float) -> dict | None:
    """The budget check on this capture's measured curve: points at k0/2, k0, 2 k0 of the law's k0."""
    from curate.evaluate.check import check_budgets, fit_check
    k0 = predict(cap["curve"], alpha_law, p, tol)
    ks = sorted(set(check_budgets(k0, cap["pool"]) + [k0]))
    pts = []
    for k in ks:
        lo = loss_at(cap["points"], k)
        if lo is None:
            continue
        pts.append({"k": k, "rho": float(cap["curve"][k - 1]), "loss": lo, "lo": lo, "hi": lo})
    if len(pts) < 2:
        return None
    chk = fit_check(pts, p, np.asarray(cap["curve"]), tol, 1.0)
    return {"k0": k0, "points": [x["k"] for x in pts], "advice": chk.budget, "low": chk.low, "high": chk.high,
            "alpha": chk.alpha}


def analyse(caps: list[dict], powers: dict) -> dict:
    out = {"captures": [], "loo": [], "product": {}}
    for c in caps:
        c["alpha"] = capture_alpha(c, powers[c["kind"]])
        out["captures"].append({k: c[k] for k in ("scene", "kind", "n", "pool", "points", "alpha")})
    renders = render_alpha()
    for kind in ("walk", "object"):
        # the product's rule: the highest alpha seen on the real captures of the kind (and, for walks,
        # the law of the rendered walks); the range, the lowest to the highest
        al = [c["alpha"] for c in caps if c["kind"] == kind and c["alpha"]]
        if kind in renders:
            al_all = al + [renders[kind][0], *renders[kind][1]]
        else:
            al_all = al
        if al:
            out["product"][kind] = {"alpha": round(max(al + ([renders[kind][0]] if kind in renders else [])), 2),
                                    "p": powers[kind], "range": [round(min(al_all), 2), round(max(al_all), 2)],
                                    "captures": [c["scene"] for c in caps if c["kind"] == kind and c["alpha"]]}
    group = (lambda c: SAME_SCENE.get(c["scene"], c["scene"]))
    for c in caps:
        p = powers[c["kind"]]
        others = [o["alpha"] for o in caps if o["kind"] == c["kind"] and group(o) != group(c) and o["alpha"]]
        if others:
            # the product's rule: the highest alpha seen (an advice short of the photos a capture
            # needs costs quality; one beyond it, a little training time)
            a, span, source = max(others), (min(others), max(others)), "other real scenes"
        elif c["kind"] in renders:
            a, span = renders[c["kind"]]
            source = "rendered walks"
        else:
            continue
        for tol in TOLS:
            kp = predict(c["curve"], a, p, tol)
            lo, hi = (predict(c["curve"], x, p, tol) for x in (min(span), max(span)))
            km, txt = measured_budget(c["points"], tol)
            chk = check_emulated(c, a, p, tol)
            out["loo"].append({"scene": c["scene"], "kind": c["kind"], "tol": tol, "pool": c["pool"], "alpha_loo": a,
                               "alpha_from": source,
                               "predicted": kp, "range": [lo, hi], "measured": km, "measured_text": txt,
                               "loss_at_predicted": loss_at(c["points"], kp), "check": chk,
                               "loss_at_check": loss_at(c["points"], chk["advice"]) if chk and chk["advice"] else None})
    return out


def markdown(res: dict) -> str:
    lines = ["| capture | kind | pool | measured loss (dB) at budget | alpha |", "|---|---|---|---|---|"]
    for c in res["captures"]:
        pts = ", ".join(f"{x['loss']:.2f} @ {x['k']}" for x in c["points"])
        lines.append(f"| {c['scene']} | {c['kind']} | {c['pool']} | {pts} | "
                     + (f"{c['alpha']:.1f}" if c["alpha"] else "—") + " |")
    lines += ["", "| capture (left out) | tolerance | predicted (range) | measured | loss at predicted | "
              "check: advice (range) from points at | loss at check's advice |", "|---|---|---|---|---|---|---|"]
    f = (lambda v: "—" if v is None else f"{v:.2f}")
    for r in res["loo"]:
        c = r["check"]
        ch = (f"{c['advice']} ({c['low']}-{c['high']}) from {', '.join(map(str, c['points']))}" if c and c["advice"]
              else "—")
        lines.append(f"| {r['scene']} | {r['tol']:g} dB | {r['predicted']} ({r['range'][0]}-{r['range'][1]}) | "
                     f"{r['measured_text']} | {f(r['loss_at_predicted'])} | {ch} | {f(r['loss_at_check'])} |")
    return "\n".join(lines)


def main(argv=None) -> dict:
    from curate.select.auto_budget import LOSS_MODEL
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--markdown", action="store_true")
    a = ap.parse_args(argv)
    res = analyse(load(a.out), {k: v[1] for k, v in LOSS_MODEL.items()})
    line = json.dumps(res)
    if a.json:
        a.json.write_text(line + "\n")
    if a.markdown:
        print(markdown(res))
    print(line)
    return res


if __name__ == "__main__":
    main()
