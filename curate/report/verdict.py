"""The verdict on a run, in words: what was exported, how much of the scene it sees, and how it
compares with random subsets, farthest-view sampling (FVS) and every n-th frame, each with its interval (95%, or 98.3%
at the looks of an evaluation that stops when decided)
and what that interval decides (ahead, behind, level within a margin, or not told apart: measured closely enough
to stop, resolved, or not).

One function, :func:`verdict`, over ``report.json``; the report's first screen and the terminal's
last lines of ``curate run`` both print it, so they never disagree. No heavy imports.
"""

from __future__ import annotations

import math

RIVALS = (("random", "random subsets of the same size", "random"), ("fvs", "farthest-view sampling (FVS)", "FVS"),
          ("stride", "every n-th frame", "every n-th frame"))
"""The rivals the verdict names: key, the words of the sentence, the words of the short line."""

FEW_VIEWS = 20
"""Under this many held-out photos in all, the verdict says the capture is too small to judge closely."""

WORDS = {"ahead": "ahead of", "behind": "behind", "level": "level with", "resolved": "not told apart from",
         "undecided": "not told apart from"}
"""What a decision (:func:`curate.core.stats.decision`) reads as, before the rival's name."""

MARGIN_DB = 0.3
"""The margin a report without one recorded (curate 0.2) is read with (``EvalConfig.margin_db``'s default)."""


def decided_as(p: dict | None) -> str | None:
    """The decision of a paired difference ``p``: its recorded ``decision``, else (a report of curate 0.2)
    the one its interval gives at :data:`MARGIN_DB`; None without an interval."""
    from curate.core.stats import decision
    if not p:
        return None
    return p.get("decision") or decision(p, float(p.get("margin", MARGIN_DB)))


def compare(p: dict | None) -> str | None:
    """'ahead of' / 'behind' / 'level with' / 'not told apart from' for a paired difference ``p`` (``mean``,
    ``lo``, ``hi``: its interval): ahead or behind where the interval excludes 0, level with where it lies
    within the margin of 0, not told apart otherwise (resolved or undecided); None without one."""
    d = decided_as(p)
    return WORDS[d] if d else None


def _db(x: float) -> str:
    return f"{x:+.2f} dB"


def _interval(p: dict) -> str:
    lo, hi = p.get("lo"), p.get("hi")
    if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
        return "no interval: too few held-out views"
    return f"{_level(p)} interval {lo:+.2f} to {hi:+.2f}"


def _level(p: dict) -> str:
    """The interval's confidence as a reader sees it: "95%", or "98.3%" for the looks of an evaluation that adds
    folds until decided (:func:`curate.evaluate.folds.look_level`); 95% when a report does not record it."""
    return f"{100 * float(p.get('level') or 0.95):.3g}%"


def _needs(p: dict) -> str:
    """What an undecided comparison needs, as the evaluation projected it (``p["needs"]``: ``folds`` more and their
    ``minutes`` on the machine that measured it; ``folds`` None: not even every photo held out)."""
    nd = p.get("needs")
    if not nd or decided_as(p) != "undecided":
        return ""
    if nd.get("folds") is None:
        return "; not even every photo held out would tell them apart"
    mins = nd.get("minutes")
    return (f"; about {nd['folds']} more folds" + (f", {_mins(mins)} here," if mins is not None else "")
            + " would decide it if the difference holds")


def _mins(m: float) -> str:
    return f"{max(1, math.ceil(m)):d} min"


def _finite(p: dict) -> bool:
    return all(isinstance(p.get(k), (int, float)) and math.isfinite(p[k]) for k in ("lo", "hi"))


def estimate_said(est: dict, run_dir: str, undecided: bool = True) -> str:
    """How the estimate was made and why it stopped, for a person (``report.json``'s ``estimate``); ``undecided``:
    some comparison is left undecided (more folds are offered only then)."""
    if not est.get("budget"):
        return ""
    n_f, planned = est.get("n_folds"), est.get("planned_folds")
    if not n_f:   # a report of curate 0.2: one hold-out
        return (f" (Estimated as cross-validation does: with every {est['holdout_every']}th photo held out "
                f"({est['n_holdout']}), the same method chose {est['budget']} of the {est['n_pool']} left"
                + (f", {est['shared_with_export']} of them exported too" if est.get("shared_with_export") is not None
                   else "") + "; the same field was trained on each subset and scored on the held-out photos.)")
    out = (f" (Estimated over {n_f} of {planned} hold-out folds, {est['n_holdout']} held-out photos: each fold held "
           f"out every {est['holdout_every']}th photo from its own offset, the same method chose {est['budget']} of "
           f"the {est['n_pool']} left, and the same field was trained on each subset and scored on the held-out "
           "photos.")
    stopped = est.get("stopped")
    if stopped == "decided":
        res = est.get("resolution_db")
        out += (" It stopped adding folds when every rival was decided"
                + (f" or its difference measured to ±{res:g} dB" if res else "") + ".)")
    elif stopped == "needs time" and not est.get("needs_minutes") and not est.get("needs_folds"):
        out += (f" It stopped after {n_f} folds: from what they show, even every photo held out would not decide the "
                "rest.)")
    elif stopped in ("time", "needs time"):
        need = est.get("needs_minutes")
        more = max(1, math.ceil(need)) if need else 2 * est.get("minutes", 15)
        out += ((f" It stopped when the {est.get('minutes', 0):g} minutes given were spent" if stopped == "time" else
                 f" It stopped after {n_f} folds: the {est.get('minutes', 0):g} minutes given would not decide the "
                 "rest")
                + f": `curate evaluate {run_dir} --eval-minutes {more:g}` adds folds, reusing the trainings done.)")
    elif stopped == "folds asked" and n_f < (est.get("holdout_every") or n_f) and undecided:
        out += (f" It trained the {n_f} folds asked for: `curate evaluate {run_dir} --folds 0` adds folds until "
                "every rival is decided.)")
    else:
        out += ")"
    return out


def verdict(rep: dict) -> dict:
    """{"exported": sentence, "frames": sentence or None (a video's: how many frames it had), "coverage": sentence
    or None, "quality": sentence, "short": one line,
    "against": {rival: 'ahead of' | 'behind' | 'level with' | 'not told apart from'}, "how_many": sentence or
    None} for a ``report.json`` dict."""
    sel = rep.get("selection") or {}
    k, n = len(sel.get("chosen") or []), rep.get("n_candidates") or rep.get("n_registered") or 0
    exported = f"{k} of {n} photos chosen" + (f" ({sel['method']})" if sel.get("method") else "")
    videos = [v for v in ((rep.get("sfm") or {}).get("videos") or []) if isinstance(v, dict) and v.get("decoded")]
    frames = None
    if videos:          # a video's frames: how many it had, and that the candidates are its usable ones
        dec = sum(int(v["decoded"]) for v in videos)
        what = videos[0].get("video", "the video") if len(videos) == 1 else f"{len(videos)} videos"
        frames = (f"The {n} candidates are the sharpest distinct frames of the {dec} in {what} that SfM "
                  "registered.")
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
        parts, short, undecided = [], [], []
        for key, words, brief in RIVALS:
            p = paired.get(f"selection-{key}")
            w = compare(p)
            if w is None:
                continue
            against[key] = w
            within = (f", within {p.get('margin', MARGIN_DB):g} dB" if decided_as(p) == "level" else
                      f", measured to ±{(p['hi'] - p['lo']) / 2:.2f} dB" if decided_as(p) == "resolved" else "")
            parts.append(f"{w} {words}{within} ({_db(p['mean'])}, {_interval(p)}{_needs(p)})")
            short.append(f"{w} {brief} {_db(p['mean'])}" + (f" [{p['lo']:+.2f}, {p['hi']:+.2f}]" if _finite(p) else ""))
            if decided_as(p) == "undecided":
                undecided.append(words)
        gap = rep.get("gap_closed")
        gap_txt = ("" if gap is None or not math.isfinite(gap) else
                   f"; it closes {100 * gap:.0f}% of the gap from random subsets to all photos" if gap > 0 else
                   "; it closes none of the gap from random subsets to all photos")
        few = ""
        if est.get("n_holdout") is not None and est["n_holdout"] < FEW_VIEWS:
            few = (f" Only {est['n_holdout']} photos could be held out: a capture this small cannot tell subsets "
                   "apart by less than the intervals' width.")
        elif undecided and est.get("stopped") == "every photo":
            few = (" Every photo has been held out once: on this capture the held-out photos differ too much from "
                   "one another to tell these subsets apart.")
        quality = ("On held-out photos the selection is " + "; ".join(parts) + gap_txt + "."
                   + estimate_said(est, rep.get("run_dir", "RUN"), bool(undecided)) + few) if parts else \
            "The evaluation has no paired comparison (too few held-out views)."
        short_line = "; ".join(short) + (f"; gap closed {100 * gap:.0f}%" if gap_txt else "") + \
            (f"; {est['n_folds']} of {est['planned_folds']} folds" if est.get("n_folds") else "")
    elif status == "out of date":
        of = ev.get("of") or {}
        quality = ("The evaluation in this run folder estimates an earlier selection "
                   f"({of.get('exported_budget', '?')} photos, {of.get('method', '?')}), not this one; "
                   f"`{ev.get('refresh')}` estimates this one.")
        short_line = f"evaluation out of date (refresh: {ev.get('refresh')})"
    else:
        quality = ("Not evaluated: no field was trained to compare this selection with random subsets and FVS"
                   f" (`{ev.get('refresh', 'curate evaluate RUN')}` does, within its time limit, `--eval-minutes`).")
        short_line = "not evaluated"
    return {"exported": exported, "frames": frames, "coverage": coverage, "quality": quality, "short": short_line,
            "against": against,
            "how_many": how_many_said(sel.get("budget_auto"), k, rep.get("budget_check"))}


LAW_ERROR = {"walk": "on real walks it advised from a quarter (a phone video of a living room) to 1.3 times (the "
                     "office) what was needed",
             "object": "on three real objects of 40-60 photos it advised 1.0-1.2 times what was needed"}
"""The law's measured error on real captures, by kind (docs/evaluation.md#how-many)."""


def how_many_said(auto: dict | None, k: int, legacy_check: dict | None = None) -> str | None:
    """``--budget auto`` in words: what was measured on this capture and exported, beside the law's prediction
    and its error on real captures; without a measurement, the law's prediction and how uncertain it is.
    ``legacy_check``: a report of curate 0.2, whose check was measured after the selection."""
    if not auto:
        return None
    law = auto.get("predicted", auto["budget"])
    rng = f" ({auto['low']} to {auto['high']})" if auto.get("low") is not None and auto["low"] != auto["high"] else ""
    tol = f"{auto['tolerance_db']:g} dB"
    err = LAW_ERROR.get(auto.get("kind"), "")
    chk = auto.get("measured")
    if chk and (chk.get("budget") is not None or chk.get("high") is not None):
        got = (f"about {chk['budget']} ({chk['low']} to {chk['high']}) photos come within {tol} of all of them"
               if chk.get("budget") is not None
               else f"{chk.get('high')} or fewer photos come within {tol} of all of them")
        return (f"How many: measured on this capture, {got}; {k} were exported. From the poses alone, the law "
                f"fitted on other captures predicted {law}{rng} ({err}).")
    out = f"How many: --budget auto predicted {law}{rng} for {tol} from the poses alone"
    if legacy_check and legacy_check.get("budget") is not None:
        return out + (f"; measured on this capture, about {legacy_check['budget']} ({legacy_check['low']} to "
                      f"{legacy_check['high']}) come within {legacy_check['tolerance_db']:g} dB.")
    return out + (f", with a law fitted on other captures: {err}. An evaluated run measures it on this capture "
                  "and exports what it measured.")
