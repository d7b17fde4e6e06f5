"""The verdict on a run, in words: what was exported, how much of the scene it sees, and how it
compares with random subsets and farthest-view sampling (FVS), each with its 95% interval.

One function, :func:`verdict`, over ``report.json``; the report's first screen and the terminal's
last lines of ``curate run`` both print it, so they never disagree. No heavy imports.
"""

from __future__ import annotations

import math

RIVALS = (("random", "random subsets of the same size"), ("fvs", "farthest-view sampling (FVS)"))
"""The baselines the verdict names, with the words it uses for them."""


def compare(p: dict | None) -> str | None:
    """'ahead of' / 'behind' / 'level with' for a paired difference ``p`` (``mean``, ``lo``, ``hi``:
    its 95% interval): ahead or behind only where the interval excludes 0; None without one."""
    if not p or p.get("lo") is None or p.get("hi") is None:
        return None
    lo, hi = float(p["lo"]), float(p["hi"])
    if not (math.isfinite(lo) or math.isfinite(hi)):
        return "level with"
    return "ahead of" if lo > 0 else "behind" if hi < 0 else "level with"


def _db(x: float) -> str:
    return f"{x:+.2f} dB"


def _interval(p: dict) -> str:
    lo, hi = p.get("lo"), p.get("hi")
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return "no interval: too few held-out views"
    return f"95% interval {lo:+.2f} to {hi:+.2f}"


def verdict(rep: dict) -> dict:
    """{"exported": sentence, "coverage": sentence or None, "quality": sentence, "short": one line,
    "against": {rival: 'ahead of' | 'level with' | 'behind'}} for a ``report.json`` dict."""
    sel = rep.get("selection") or {}
    k, n = len(sel.get("chosen") or []), rep.get("n_candidates") or rep.get("n_registered") or 0
    exported = f"{k} of {n} photos chosen" + (f" ({sel['method']})" if sel.get("method") else "")
    cov = sel.get("coverage")
    coverage = None
    if cov and cov.get("n_nodes_seen"):
        coverage = (f"They see {100 * cov['seen']:.0f}% of the scene the whole capture sees "
                    f"({100 * cov['seen_twice']:.0f}% from at least two of them).")
    ev = rep.get("evaluation") or {}
    status = ev.get("status", "not run")
    against: dict[str, str] = {}
    if status == "current" and "selection" in (rep.get("methods") or {}):
        paired = rep.get("paired") or {}
        est = rep.get("estimate") or {}
        pr = (f" (Estimated as cross-validation does: with every {est['holdout_every']}th photo held out "
              f"({est['n_holdout']}), the same method chose {est['budget']} of the {est['n_pool']} left"
              + (f", {est['shared_with_export']} of them exported too" if est.get("shared_with_export") is not None
                 else "") + "; the same field was trained on each subset and scored on the held-out photos.)"
              if est.get("budget") else "")
        parts, short = [], []
        for key, words in RIVALS:
            p = paired.get(f"selection-{key}")
            w = compare(p)
            if w is None:
                continue
            against[key] = w
            parts.append(f"{w} {words} ({_db(p['mean'])}, {_interval(p)})")
            short.append(f"{w} {'FVS' if key == 'fvs' else key} {_db(p['mean'])} "
                         f"[{p['lo']:+.2f}, {p['hi']:+.2f}]" if math.isfinite(p.get("lo", math.nan))
                         and math.isfinite(p.get("hi", math.nan)) else f"{w} {key} {_db(p['mean'])}")
        gap = rep.get("gap_closed")
        gap_txt = ("" if gap is None or not math.isfinite(gap) else
                   f"; it closes {100 * gap:.0f}% of the gap from random subsets to all photos" if gap > 0 else
                   "; it closes none of the gap from random subsets to all photos")
        quality = ("On held-out photos the selection is " + "; ".join(parts) + gap_txt + "." + pr) if parts else \
            "The evaluation has no paired comparison (too few held-out views)."
        short_line = "; ".join(short) + (f"; gap closed {100 * gap:.0f}%" if gap_txt else "")
    elif status == "out of date":
        of = ev.get("of") or {}
        quality = (f"The evaluation in this run folder estimates an earlier selection ({of.get('exported_budget', '?')} "
                   f"photos, {of.get('method', '?')}), not this one; `{ev.get('refresh')}` estimates this one.")
        short_line = f"evaluation out of date (refresh: {ev.get('refresh')})"
    else:
        quality = ("Not evaluated: no field was trained to compare this selection with random subsets and FVS"
                   f" (`{ev.get('refresh', 'curate evaluate RUN')}` does, in a few minutes).")
        short_line = "not evaluated"
    how_many = None
    chk, auto = rep.get("budget_check"), sel.get("budget_auto")
    if auto:
        how_many = (f"How many: --budget auto predicted {auto['budget']}"
                    + (f" ({auto['low']} to {auto['high']})" if auto.get("low") is not None
                       and auto["low"] != auto["high"] else "")
                    + f" for {auto['tolerance_db']:g} dB from the poses alone")
        if chk and chk.get("budget") is not None:
            how_many += (f"; measured on this capture, about {chk['budget']} ({chk['low']} to {chk['high']}) come "
                         f"within {chk['tolerance_db']:g} dB")
            if chk["low"] > k:
                how_many += f": the export has {k}, `curate select {rep.get('run_dir', 'RUN')} --budget {chk['budget']}` " \
                            "takes more"
        elif chk and chk.get("high") is not None:
            how_many += f"; measured on this capture, {chk['high']} or fewer suffice"
        elif not chk:
            how_many += (" (a rule fitted on other captures; on a real phone video it once advised a third of what "
                         "was needed: the evaluation measures it on this capture)")
        how_many += "."
    return {"exported": exported, "coverage": coverage, "quality": quality, "short": short_line, "against": against,
            "how_many": how_many}
