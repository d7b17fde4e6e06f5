"""The evaluate stage: how good is the exported selection, against its rivals? -> ``RUN/evaluate``.

The exported selection is chosen from every registered photo (:mod:`curate.select.stage`), so no photo of it
can be held out to test it. Its quality is estimated as cross-validation estimates a model trained on all the
data, over hold-out folds (:mod:`curate.evaluate.folds`): each fold holds out every ``holdout_every``-th
registered photo from its own offset, the same method (same options) chooses the same share of the photos
left, and the same field is trained on that choice, on random subsets of its size, on farthest-view sampling
(FVS), on every n-th frame (photos in capture order) and on all the photos left, each scored on the fold's
held-out photos. The differences are paired per held-out photo and pooled over the folds. Folds are added
(:mod:`curate.evaluate.schedule`) until every rival is decided (ahead, behind, level within ``margin_db``, or
its interval at most ``resolution_db`` wide on each side), every photo has been held out once, or ``minutes`` are
spent; ``--folds N`` trains exactly N.
Each training is a stage of its own (``RUN/evaluate/<unit>/stage.json``), so a killed evaluation resumes, and
a later one with more time reuses them.

``RUN/evaluate/summary.json``, then ``stage.json`` (last, as every stage's): ``key`` (the evaluation's options and the
selection it estimates), ``inputs`` ({"select": its key}: a later selection makes it out of date,
:func:`curate.core.stage.stale_stages`), ``methods``, ``paired``, ``gap_closed``
(:func:`curate.evaluate.folds.summarize`) and ``protocol`` (:func:`protocol`). How many photos ``--budget auto``
exports is measured before the selection, by :mod:`curate.evaluate.budget`.
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from curate.core.paths import RunPaths
from curate.core.stage import StageResult

if TYPE_CHECKING:
    from curate.config import RunConfig
    from curate.core.graph import RunContext

log = logging.getLogger(__name__)

STOPPED = {"decided": "every rival decided or resolved", "every photo": "every photo held out once",
           "folds asked": "the folds asked for done", "time": "the time given was spent",
           "needs time": "the folds the time holds would not decide what is undecided"}
"""Why the evaluation stopped adding folds (``protocol.stopped``), in words."""


def eval_key(cfg: "RunConfig", run_dir: Path) -> str:
    """The evaluation's key: its options (not the workers) and the selection it estimates."""
    from curate.core.stage import current_key, stage_key
    parts = {"evaluate": replace(cfg.evaluate, workers=0), "select": cfg.select}
    return stage_key(parts, [current_key(run_dir, "select") or "", current_key(run_dir, "sfm") or ""])


def unit_key(cfg: "RunConfig", sfm_key: str, unit, fold) -> str:
    """A training's stage key: the training settings, its subset and its fold's held-out photos."""
    from curate.core.stage import stage_key
    return stage_key({"train": cfg.evaluate.training(), "subset": unit.subset, "holdout": fold.holdout}, [sfm_key])


def protocol(cfg: "RunConfig", folds: list, exported: list[int], n_registered: int, planned: int, looks: list[int],
             level: float, stopped: str, seconds: float) -> dict:
    """``summary.json``'s ``protocol``: the folds (each :meth:`curate.evaluate.folds.Fold.record`), how many were
    planned, when they were looked at and at which level, why it stopped; and, for a reader of one figure, the
    first fold's ``budget``, ``method`` and ``shared_with_export``, ``n_pool`` and the held-out photos of all."""
    ev = cfg.evaluate
    f0 = folds[0]
    return {"holdout_every": ev.holdout_every, "n_registered": n_registered, "exported_budget": len(exported),
            "folds": [f.record(exported) for f in folds], "n_folds": len(folds), "planned_folds": planned,
            "looks": looks, "level": level, "margin_db": ev.margin_db, "resolution_db": ev.resolution_db,
            "minutes": ev.minutes, "stopped": stopped,
            "seconds": round(seconds, 1), "budget": f0.budget, "method": f0.method, "n_pool": len(f0.pool),
            "shared_with_export": f0.record(exported)["shared_with_export"],
            "holdout": sorted(c for f in folds for c in f.holdout)}


def evaluation_current(run_dir: Path, key: str) -> bool:
    """The evaluation finished with ``key`` and its files are there: its summary, its ground truth and every
    training it pooled (each unit's own record and files); an evaluation of an earlier curate, with only its
    ``summary.json`` (or no list of units), by its key alone."""
    from curate.core.stage import finished_record, read_stage, up_to_date
    d = RunPaths(run_dir).evaluate
    if read_stage(d) is None:
        return (finished_record(run_dir, "evaluate") or {}).get("key") == key
    now = up_to_date(d, key)
    if not now.fresh:
        if now.missing:
            log.warning("%s: %s missing: the evaluation is done again (its finished trainings are reused)", d,
                        ", ".join(now.missing[:3]))
        return False
    gone = [u for u in (read_stage(d) or {}).get("units") or () if not up_to_date(d / u, (read_stage(d / u) or
                                                                                          {}).get("key", "")).fresh]
    if gone:
        log.warning("%s: the training(s) %s are incomplete: done again", d, ", ".join(gone[:3]))
    return not gone


def wanted(cfg: "RunConfig", run_dir: Path) -> bool:
    """The stage runs: the run is evaluated (not ``--no-evaluate``)."""
    return cfg.run_evaluation


def evaluate(ctx: "RunContext") -> StageResult:
    """Train the folds' units until decided (finished units are reused) -> ``RUN/evaluate``.

    ``ctx.executor``: a ``concurrent.futures.Executor`` for the trainings (None: local processes).
    """
    from curate.core.stage import current_key, finish_stage, inputs_of, write_json_atomic
    from curate.evaluate.folds import (ALL_FOLDS, fold_order, in_capture_order, look_level, looks, plan_fold,
                                       planned_folds, summarize)
    from curate.evaluate.schedule import run_folds
    from curate.evaluate.units import EVAL_OWN, clear_evaluation, eval_cameras, evaluation_folder, resolved
    from curate.field.train import default_box
    from curate.core.run import load_node_grid, read_selection
    from curate.sfm.io import image_paths, load_sfm

    t0 = time.perf_counter()
    cfg, run_dir, force, executor = ctx.cfg, ctx.run_dir, ctx.force, ctx.executor
    d = RunPaths(run_dir).evaluate
    ev = cfg.evaluate
    key = eval_key(cfg, run_dir)
    if force:
        kept = clear_evaluation(run_dir)  # only what curate wrote there (curate.core.runfolder)
        if kept:
            log.warning("%s: kept %d file(s) of yours there (%s...): curate removes only what it wrote", d, len(kept),
                        kept[0].relative_to(d).as_posix())
    elif evaluation_current(run_dir, key):
        return StageResult("evaluate", d, False, time.perf_counter() - t0)
    ev_run = resolved(ev)            # the device, chosen once for every training
    earlier = earlier_needs(run_dir)
    evaluation_folder(run_dir)
    (d / "stage.json").unlink(missing_ok=True)   # an earlier evaluation's record: this one replaces it
    sel = read_selection(run_dir)
    exported = [int(c) for c in sel["chosen"]]
    sfm = load_sfm(run_dir)
    cams = sfm.cameras
    n = len(cams)
    grid = load_node_grid(run_dir)
    ordered = "stride" in ev.methods and in_capture_order(cams, grid.nodes())
    order = fold_order(ev.holdout_every, n)[:planned_folds(ev, n)]
    if not order:
        raise ValueError(f"no photo to hold out from {n} registered photos: register more photos")
    adaptive = ev.folds == 0
    look_at, level = looks(len(order), adaptive), look_level(adaptive, len(order))
    sfm_key = current_key(run_dir, "sfm") or ""
    planner = Planner(ev, len(order), level, adaptive)
    planner.extend = earlier
    from curate.core.plan import plan_of_run
    chosen_by = replace(cfg.select, method=plan_of_run(cfg, run_dir).method)   # the exported selection's method

    def make_fold(offset: int):
        return plan_fold(ev, chosen_by, cams, grid, len(exported), offset, ordered,
                         with_all=order.index(offset) < ALL_FOLDS)

    def keyed(u, f):
        return unit_key(cfg, sfm_key, u, f)
    paths = image_paths(run_dir, list(cams.names), sfm.records)
    planner.t0 = time.monotonic()
    folds, res, stopped = run_folds(run_dir, ev_run, make_fold, order, look_at, planner.look,
                                    eval_cameras(cams, ev.train_side()), paths, default_box(cams), keyed, adaptive,
                                    executor=executor, on_trained=planner.trained, on_fold=planner.forecast)
    if stopped == "all folds" or (stopped == "decided" and not adaptive):   # --folds N: all N ran, as asked
        stopped = "every photo" if len(order) == min(ev.holdout_every, n) else "folds asked"
    methods, paired, gap = summarize(res, folds, level, ev.margin_db, rival_folds=planner.rival_folds(),
                                     resolution=ev.resolution_db)
    planner.needs_said(paired, len(folds), stopped)
    seconds = time.perf_counter() - t0
    summary = {"key": key, "inputs": inputs_of(run_dir, "evaluate"), "methods": methods, "paired": paired,
               "gap_closed": gap,
               "protocol": {**protocol(cfg, folds, exported, n, len(order), planner.looked or look_at, level,
                                       stopped, seconds), "plan": planner.record()}}
    write_json_atomic(d / "summary.json", summary)
    finish_stage(d, key, {"evaluate": replace(ev, workers=0), "select": cfg.select}, t0,
                 outputs={"summary": "summary.json"}, owns=EVAL_OWN, stopped=stopped, n_folds=len(folds),
                 units=sorted(u.key for f in folds for u in f.units))
    txt = ", ".join(f"{m} {v['psnr']:.2f}" for m, v in methods.items())
    views = sum(len(f.holdout) for f in folds)
    return StageResult("evaluate", d, True, seconds,
                       f"{len(folds)} of {len(order)} folds ({views} held-out photos; {STOPPED[stopped]}); "
                       f"held-out PSNR {txt}")



def earlier_needs(run_dir: Path) -> dict[str, int]:
    """{rival: the folds an earlier evaluation of the same selection said would decide it} (the folds its comparison
    used plus ``paired[...]["needs"]["folds"]``), so that ``curate evaluate RUN --eval-minutes M`` trains the folds
    the verdict asked for instead of stopping where the earlier plan stopped; {} without one."""
    import json

    from curate.core.stage import inputs_of
    try:
        s = json.loads((RunPaths(run_dir).evaluate / "summary.json").read_text())
    except (OSError, ValueError):
        return {}
    if s.get("inputs") != inputs_of(run_dir, "evaluate"):
        return {}
    out = {}
    for k, p in (s.get("paired") or {}).items():
        more = (p.get("needs") or {}).get("folds")
        if more and p.get("n_folds"):
            out[k.split("-", 1)[1]] = int(p["n_folds"]) + int(more)
    return out


class Planner:
    """The evaluation's looks and plan: what a training costs here, which rivals each look decides, how many more
    folds the undecided need and whether the time given holds them (:func:`curate.evaluate.folds.plan_rivals`), and
    the lines that say so on the terminal. ``look`` is :func:`curate.evaluate.schedule.run_folds`'s ``stop_at``,
    ``trained`` its ``on_trained``."""

    def __init__(self, ev, planned: int, level: float, adaptive: bool, say=None):
        self.ev, self.planned, self.level, self.adaptive = ev, planned, level, adaptive
        self.say = say or _say
        self.t0 = time.monotonic()
        self.seconds: list[float] = []      # wall seconds of each training finished now
        self.workers = 1
        self.decided_at: dict[str, int] = {}   # rival -> the finished folds of the look that decided it
        self.closed_at: dict[str, int] = {}    # rival -> the finished folds of its last look, left undecided
        self.until: dict[str, int] = {}        # rival -> the folds it is trained in (its next look)
        self.n_looks: dict[str, int] = {}      # rival -> its looks so far
        self.extend: dict[str, int] = {}       # rival -> the folds an earlier evaluation said decide it
        self.looked: list[int] = []
        self.plans: list[dict] = []
        self.needs: dict[str, dict] = {}
        self.needs_minutes: float | None = None
        self.forecast_folds: dict | None = None

    def to_decide(self, p: dict, max_folds: int, last: bool = False) -> int | None:
        """:func:`curate.evaluate.folds.next_look` of ``p`` at this evaluation's margin and resolution."""
        from curate.evaluate.folds import next_look
        return next_look(p, self.ev.margin_db, max_folds, self.ev.resolution_db, last)

    def unit_s(self) -> float | None:
        import numpy as np
        return float(np.median(self.seconds)) if self.seconds else None

    def rival_units(self, r: str) -> int:
        """Trainings of rival ``r`` in a fold: ``--random-seeds`` for random subsets, one for the others."""
        return self.ev.random_seeds if r == "random" else 1

    def rival_fold_s(self, r: str, unit_s: float) -> float:
        """Seconds here of one more fold for rival ``r`` alone: its trainings and the selection's, ``unit_s`` each,
        ``workers`` at a time."""
        return (1 + self.rival_units(r)) * unit_s / max(self.workers, 1)

    def fold_s(self, n_units: int) -> float | None:
        u = self.unit_s()
        return None if u is None else n_units * u / max(self.workers, 1)

    def trained(self, seconds: float, workers: int) -> None:
        self.seconds.append(float(seconds))
        self.workers = workers
        if len(self.seconds) == 1 and self.adaptive:
            n_units = 1 + len(self.ev.methods) - 1 + max(self.ev.random_seeds - 1, 0)
            fold = self.fold_s(n_units)
            left = 60 * self.ev.minutes - (time.monotonic() - self.t0)
            self.say(f"evaluate: a training takes {seconds:.0f} s here ({workers} at a time): a fold of up to "
                     f"{n_units} trainings about {_minutes(fold)}; the {self.ev.minutes:g} minutes given hold about "
                     f"{max(int(left // fold), 2) if fold else '?'} folds (the verdict is first read after "
                     f"{_first_look()})")

    def forecast(self, folds: list, results: dict) -> None:
        """After the first fold (no look: nothing is decided on it): how many folds each comparison is expected
        to need, and how long that takes here, from the prior's interval of one fold."""
        from curate.evaluate.config import RIVALS
        from curate.evaluate.folds import summarize
        if len(folds) != 1 or not self.adaptive:
            return
        _, paired, _ = summarize(results, folds, self.level, self.ev.margin_db, resolution=self.ev.resolution_db)
        needs = {r: self.to_decide(paired[f"selection-{r}"], self.planned)
                 for r in RIVALS if f"selection-{r}" in paired}
        unit_s = self.unit_s()             # None: every training so far was reused (no cost measured here)
        self.forecast_folds = needs
        parts = []
        for r, g in sorted(needs.items(), key=lambda kv: (kv[1] is None, kv[1] or 0)):
            if g is None:
                parts.append(f"{RIVAL_WORDS[r]}: more folds than the capture has")
                continue
            if unit_s is None:
                parts.append(f"{RIVAL_WORDS[r]}: about {g} folds")
                continue
            parts.append(f"{RIVAL_WORDS[r]}: about {g} folds ({_minutes(g * self.rival_fold_s(r, unit_s))} here)")
        self.say("evaluate: from the first fold, a decision needs " + "; ".join(parts))

    def look(self, folds: list, results: dict):
        """A look at the finished ``folds``, for the rivals whose own look it is (the first look: every rival;
        then each rival at the fold count its plan projected, on the folds where it and the selection were both
        trained): decided rivals are closed; each undecided one is projected
        (:func:`curate.evaluate.folds.folds_to_decide`) and trained on only to the folds its own comparison needs,
        when the time left holds them beside the others' (:func:`curate.evaluate.folds.plan_rivals`), else closed;
        a rival is looked at :data:`curate.evaluate.folds.LOOKS` times at most. The selection is trained in every
        fold any rival still needs (the comparisons are paired per fold). Stops when no rival is left."""
        from curate.evaluate.config import RIVALS
        from curate.core.stats import DECIDED
        from curate.evaluate.folds import LOOKS, plan_rivals, summarize
        from curate.evaluate.schedule import Look
        F = len(folds)
        self.looked.append(F)
        _, paired, _ = summarize(results, folds, self.level, self.ev.margin_db, rival_folds=self.rival_folds(),
                                 resolution=self.ev.resolution_db)
        due, pending = [], {}
        for r in RIVALS:
            p = paired.get(f"selection-{r}")
            if p is None or r in self.decided_at or r in self.closed_at:
                continue
            if r in self.until and self.until[r] > F and F < self.planned:
                pending[r] = self.until[r]            # its own look is later
                continue
            self.n_looks[r] = self.n_looks.get(r, 0) + 1
            if p["decision"] in DECIDED:
                self.decided_at[r] = F
            elif self.n_looks[r] >= LOOKS or F >= self.planned or not self.adaptive:
                self.closed_at[r] = F                  # its last look: undecided
            else:
                due.append(r)
        rec = {"folds": F, "decided": {r: paired[f"selection-{r}"]["decision"] for r in self.decided_at
                                       if self.decided_at[r] == F}}
        if not self.adaptive:
            self.plans.append(rec)
            return Look()
        needs = {r: self.to_decide(paired[f"selection-{r}"], self.planned, last=self.n_looks[r] == LOOKS - 1)
                 for r in due}
        left = 60 * self.ev.minutes - (time.monotonic() - self.t0)
        unit_s = self.unit_s() or 0.0
        floor = {r: min(max(needs[r], self.extend.get(r, 0)), self.planned) for r in due
                 if needs[r] is not None and self.n_looks[r] == LOOKS - 1 and self.extend.get(r, 0) > needs[r]}
        needs.update(floor)                         # a later evaluation adds the folds an earlier one said it needs
        taken, _ = plan_rivals(needs, F, self.ev.random_seeds, unit_s, self.workers, left, committed=pending)
        # a rival's last look goes no earlier than the last fold the selection is trained to for the others: its
        # own trainings there are all it costs, and the folds it gains are power (the drone flight's random
        # subsets, looked at last after 7 folds, were 0.02 dB short of deciding; FVS was trained to 10 anyway)
        horizon = max([needs[r] for r in taken] + list(pending.values()), default=F)
        later = {r: horizon for r in taken if self.n_looks[r] == LOOKS - 1 and needs[r] < horizon}
        if later and set(plan_rivals({**{r: needs[r] for r in taken}, **later}, F, self.ev.random_seeds, unit_s,
                                     self.workers, left, committed=pending)[0]) == set(taken):
            needs.update(later)
        for r in due:
            if r in taken:
                self.until[r] = needs[r]
            else:
                self.closed_at[r] = F                  # not pursued: its need does not fit, or is beyond the folds
        open_ = {r: self.until[r] for r in (*pending, *taken)}
        if due:
            rec.update({"needs_folds": needs, "training": taken,
                        "next_look": max(open_.values()) if open_ else None,
                        "unit_seconds": round(unit_s, 1), "seconds_left": round(left, 1)})
        self.plans.append(rec)
        self.say(self.plan_said(F, paired, needs, taken, pending))
        if not open_:
            undecided = any(r in self.closed_at for r in RIVALS)
            why = "decided" if not undecided else ("all folds" if F >= self.planned else "needs time")
            return Look(stop=True, why=why, skip=frozenset(RIVALS))
        until = {r: (open_[r] if r in open_ else F) for r in RIVALS}
        until["selection"] = max(open_.values())
        return Look(skip=frozenset(set(RIVALS) - set(open_)), next_look=min(open_.values()), until=until,
                    also=tuple(sorted(set(open_.values()))))

    def rival_folds(self) -> dict[str, int]:
        """{rival: the leading folds its comparison uses}: those of the look that decided it, or of its last look
        (a rival not pursued); rivals still open use every fold trained with them."""
        return {**self.closed_at, **self.decided_at}

    def plan_said(self, F: int, paired: dict, needs: dict, taken: list, pending: dict) -> str:
        """What a look decided and plans, one part per rival (the plan lines the terminal shows)."""
        from curate.evaluate.config import RIVALS
        unit_s = self.unit_s()
        parts = []
        for r in RIVALS:
            p = paired.get(f"selection-{r}")
            if p is None:
                continue
            w = RIVAL_WORDS[r]
            if r in self.decided_at:
                parts.append(f"{w}: {paired[f'selection-{r}']['decision']}, decided after {self.decided_at[r]} folds")
                continue
            if r in pending:
                parts.append(f"{w}: looked at again after {pending[r]} folds, as planned")
                continue
            more = None if needs.get(r) is None else needs[r] - F
            cost = f", ~{_minutes(more * self.rival_fold_s(r, unit_s))} here" if unit_s and more is not None else ""
            if r in taken:
                parts.append(f"{w}: {more} more folds{cost}")
                continue
            if r not in needs:                          # closed at an earlier look, or its last look now
                parts.append(f"{w}: undecided after {self.closed_at.get(r, F)} folds")
                continue
            if needs[r] is None:
                far = self.to_decide(p, FAR_FOLDS) if p.get("mean") is not None else None
                parts.append(f"{w}: would need ~{far} folds, more than the capture's {self.planned}: not pursued"
                             if far else f"{w}: would stay undecided even with every photo held out: not pursued")
                continue
            parts.append(f"{w}: would need {more} more folds{cost}, beyond --eval-minutes: not pursued")
        return f"evaluate: after {F} folds: " + "; ".join(parts)

    def needs_said(self, paired: dict, n_folds: int, stopped: str) -> None:
        """For each rival left undecided: the folds and minutes here that the projection says would decide it
        (``paired[...]["needs"]``: ``folds`` more, ``minutes``; ``folds`` None: not even with every photo held
        out); and the minutes all of them need together (``needs_minutes``: the folds trained with the selection
        and each rival that still needs them)."""
        unit_s = self.unit_s()
        need: dict[str, int] = {}
        for key, p in paired.items():
            if p.get("decision") != "undecided" or p.get("mean") is None:
                continue
            g = self.to_decide(p, self.planned)
            more = None if g is None else max(g - int(p.get("n_folds") or n_folds), 0)
            r = key.split("-", 1)[1]
            minutes = None if (more is None or unit_s is None) else more * self.rival_fold_s(r, unit_s) / 60
            p["needs"] = {"folds": more, "minutes": None if minutes is None else round(minutes, 1)}
            self.needs[key] = p["needs"]
            if more:
                need[r] = more
        if need and unit_s is not None:
            self.needs_minutes = round(sum(
                1 + sum(self.rival_units(r) for r in need if need[r] >= g)
                for g in range(1, max(need.values()) + 1)) * unit_s / max(self.workers, 1) / 60, 1)

    def record(self) -> dict:
        """``summary.json``'s ``protocol.plan``: the cost of a training here, the first fold's forecast (the folds
        each rival was expected to need), each look's plan, what the undecided need."""
        u = self.unit_s()
        return {"unit_seconds": None if u is None else round(u, 1), "workers": self.workers,
                "trainings_now": len(self.seconds), "forecast": self.forecast_folds, "looks": self.plans,
                "needs": self.needs, "needs_minutes": self.needs_minutes}


def _say(msg: str) -> None:
    from tqdm import tqdm
    tqdm.write(msg)


def _minutes(seconds: float | None) -> str:
    if seconds is None:
        return "?"
    return f"{seconds:.0f} s" if seconds < 90 else f"{seconds / 60:.1f} min"


def _first_look() -> str:
    from curate.evaluate.folds import FIRST_LOOK
    return f"{FIRST_LOOK} folds"


RIVAL_WORDS = {"random": "random subsets", "fvs": "FVS", "stride": "every n-th frame"}

FAR_FOLDS = 200
"""How far the plan's words project a comparison that the capture's folds would not decide ("would need ~40
folds"): beyond it, "would stay undecided"."""
