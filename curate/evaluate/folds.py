"""The hold-out folds of the evaluation: which photos each holds out, what it trains, in what order, and what
the folds say together.

Fold ``o`` holds out the registered photos ``o, o + n, o + 2n, ...`` (``n`` = ``EvalConfig.holdout_every``);
the same method, with the same options, chooses the exported share of the photos left, and the rivals
(random subsets, farthest-view sampling, every n-th frame) take as many; all photos left are the ceiling.
Over ``n`` folds every photo is held out once. Folds are trained in :func:`fold_order` (spread over the
capture, so that a few folds already sample all of it), and their per-photo differences are pooled
(:func:`curate.core.stats.folds_paired`).

No torch here: the trainings are :mod:`curate.evaluate.units`, their scheduling :mod:`curate.evaluate.schedule`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from curate.evaluate.config import RIVALS, EvalConfig
from curate.evaluate.units import Unit

FOLD_SEED = 1000
"""Random draw ``s`` of fold ``o`` uses seed ``FOLD_SEED * o + s``: every fold draws its own subsets."""

ALL_FOLDS = 1
"""Folds that also train on all the photos left (the ceiling of the gap closed): the first, whose trainings always
run; the comparisons with the rivals use every fold. (Two until 0.3: a fifth of the first two folds' trainings,
for a figure the verdict does not rest on; the budget stage's learning curve still trains both of its own.)"""

KAPPA_PRIOR = (1.0, 8.0)
"""The prior of the verdict's interval (:func:`curate.core.stats.folds_moderated`): ``(kappa0, nu0)``, the design
effect of the pooled mean (how much more, or less, it varies than if every held-out view were an independent
draw) and how many degrees of freedom of folds it is worth. ``kappa0 = 1``: as if the held-out views were
independent, above every design effect measured on real captures (0.03 to 1.0 over two folds, 0.16 to 0.52 over
the 14 folds of the office walk: folds interleave along the capture and agree more closely than independent views
would), so the prior is cautious there; ``nu0 = 8``: the most weight at which the null simulation, with fold
effects larger than measured (design effects up to 2), still calls a difference that is not there in at most 5%
of captures (``research/null_sim.py``, ``research/interval_study.py``; docs/evaluation.md#two-folds)."""

LOOKS = 3
"""How often each rival's comparison is looked at, at most: after :data:`FIRST_LOOK` folds, at the fold count that
look projects it to need (:func:`plan_rivals`), and at the fold count the second look projects (or when the time
or the folds run out first). Each rival has its own looks, on the folds where it and the selection were both
trained. Each look uses a ``1 - 0.05 / LOOKS`` interval, so that stopping at a decided look keeps each verdict's
error at 5% (Bonferroni over the looks; docs/evaluation.md#folds-until-decided)."""

LAST_LOOK_POWER = 0.84
"""A rival's last look is planned where a mean difference that holds would decide it with about 80% chance (the
interval's edge that many standard errors inside the mean: :func:`folds_to_decide`'s ``power``), not an even
one: undecided there, a rival is trained no more. Planned at an even chance, the last look left random subsets
undecided on the drone flight (projected 5 folds, needed 7) and on the fox (its interval's lower end at -0.04
dB; docs/evaluation.md#resolved)."""

FIRST_LOOK = 2
"""Folds after which the evaluation first decides whether to stop (and plans what to train next). Folds
interleave (every 14th photo from offsets 0, 7, 3, 10): each samples the whole capture, and the interval's prior
(:data:`KAPPA_PRIOR`) says how much the folds share, so two already give an interval a user can act on."""


def fold_order(every: int, n: int | None = None) -> list[int]:
    """The offsets ``0 .. every - 1`` in the order folds are trained: each next one the farthest, around the
    circle of offsets, from those taken (ties: the lowest), e.g. 0, 7, 3, 10, 1, 5, 8, 12, ... for 14. With
    ``n`` (the photos), only the offsets that hold out a photo (``< n``), in the same order."""
    every = int(every)
    if every < 1:
        return []
    order = [0]
    while len(order) < every:
        left = [o for o in range(every) if o not in order]
        dist = [min(min(abs(o - t), every - abs(o - t)) for t in order) for o in left]
        order.append(left[int(np.argmax(dist))])
    return order if n is None else [o for o in order if o < n]


def planned_folds(cfg: EvalConfig, n_registered: int) -> int:
    """How many folds the evaluation may train: ``cfg.folds`` when given, else ``holdout_every`` (every photo
    held out once); never more folds than offsets that hold out a photo."""
    m = min(cfg.holdout_every, max(n_registered, 0))
    return min(cfg.folds, m) if cfg.folds else m


def looks(n_folds: int, adaptive: bool) -> list[int]:
    """After how many finished folds the evaluation decides whether to stop: with ``adaptive`` (``--folds
    0``) after :data:`FIRST_LOOK` and after all of them (a time-out before then is the last look; the first look
    may plan one more between: :func:`plan_rivals`); otherwise only at the end."""
    if not adaptive or n_folds <= FIRST_LOOK:
        return [n_folds]
    return [FIRST_LOOK, n_folds]


def look_level(adaptive: bool, n_folds: int | None = None) -> float:
    """The confidence level of each look's interval: ``1 - 0.05 / LOOKS`` when the evaluation may stop at an
    earlier look (``adaptive`` with more than :data:`FIRST_LOOK` folds planned; ``n_folds`` None: assume so),
    else 95% (one look)."""
    many = adaptive and (n_folds is None or len(looks(n_folds, True)) > 1)
    return 1 - 0.05 / LOOKS if many else 0.95


@dataclass
class Fold:
    """One hold-out fold: its split, its estimate of the selection and its units."""

    offset: int
    holdout: list[int]
    """Held-out camera indices (every ``holdout_every``-th from ``offset``)."""
    pool: list[int]
    """The other camera indices, which the subsets are chosen from."""
    budget: int
    """The exported share of ``pool``."""
    method: str
    """What the selection ran (auto resolved)."""
    chosen: list[int]
    """The fold's selection (camera indices)."""
    units: list[Unit] = field(default_factory=list)

    def record(self, exported: list[int]) -> dict:
        """The fold as ``summary.json`` records it."""
        return {"offset": self.offset, "holdout": self.holdout, "n_pool": len(self.pool), "budget": self.budget,
                "method": self.method, "chosen": self.chosen,
                "shared_with_export": len(set(self.chosen) & set(exported)),
                "units": {u.key: u.method for u in self.units}}


def eval_budget(n_exported: int, n_all: int, n_pool: int) -> int:
    """A fold's budget: the exported fraction ``n_exported / n_all`` of the ``n_pool`` photos left after the
    hold-out, rounded, at least 2 and fewer than ``n_pool``."""
    k = int(round(n_exported * n_pool / max(n_all, 1)))
    return int(min(max(k, 2), max(n_pool - 1, 2)))


def in_capture_order(cams, nodes=None) -> bool:
    """The photos form a path in name order (a video, numbered frames): every n-th frame is then a rival."""
    from curate.select.medoids import embed, path_steps, view_depths
    return path_steps(*embed(cams, view_depths(cams, nodes))) is not None


def whole_capture_method(select_cfg, cams):
    """``select_cfg`` with "auto" resolved on the whole capture ``cams``, as the exported selection resolved it
    (:func:`curate.select.methods.resolve_method`), so that a fold's smaller pool runs the same method. In a run the
    stages pass the method the plan resolved (:mod:`curate.core.plan`), and this returns it as it is; a caller with
    ``auto`` (a research harness) gets it resolved here, once per fold."""
    from dataclasses import replace

    from curate.select.methods import resolve_method
    if select_cfg.method != "auto":
        return select_cfg
    return replace(select_cfg, method=resolve_method(cams, select_cfg.method)[0])


def plan_fold(cfg: EvalConfig, select_cfg, cams, grid, n_exported: int, offset: int, ordered: bool,
              with_all: bool = True) -> Fold:
    """Fold ``offset`` of ``cams`` (every registered camera): its split, its selection (``select_cfg`` on
    ``grid``) and its units, in the order they are trained: the selection, the rivals (every n-th frame only
    when ``ordered``), all photos (only ``with_all``: the ceiling is measured on the first :data:`ALL_FOLDS`
    folds, the comparisons on every fold)."""
    from curate.core.stats import holdout_split
    from curate.select.baselines import farthest_view, random_subset, stride_subset
    from curate.select.select import select
    from curate.select.visibility import build_pair_index
    select_cfg = whole_capture_method(select_cfg, cams)
    pool, hold = (v.tolist() for v in holdout_split(len(cams), cfg.holdout_every, offset))
    if not hold:
        raise ValueError(f"fold {offset}: no photo to hold out from {len(cams)} registered photos")
    if len(pool) < 3:
        raise ValueError(f"only {len(pool)} registered photos left after holding out every {cfg.holdout_every}th: "
                         "too few to evaluate (use --no-evaluate)")
    k = eval_budget(n_exported, len(cams), len(pool))
    pc = cams[pool]
    index = build_pair_index(pc, grid.nodes(), select_cfg.energy.bins, device=select_cfg.device)
    sel = select(pc, grid, k, select_cfg, index=index)
    chosen = [pool[i] for i in sel.chosen]
    tag = f"f{offset:02d}"
    units = []
    for m in cfg.methods:
        if m == "selection":
            units.append(Unit(f"{tag}_selection", "selection", None, chosen, offset))
        elif m == "random":
            units += [Unit(f"{tag}_random_s{s}", "random", FOLD_SEED * offset + s,
                           [pool[i] for i in random_subset(len(pool), k, FOLD_SEED * offset + s)], offset)
                      for s in range(cfg.random_seeds)]
        elif m == "fvs":
            units.append(Unit(f"{tag}_fvs", "fvs", None, [pool[i] for i in farthest_view(pc, k)], offset))
        elif m == "stride" and ordered:
            units.append(Unit(f"{tag}_stride", "stride", None, [pool[i] for i in stride_subset(len(pool), k)], offset))
        elif m == "all" and with_all:
            units.append(Unit(f"{tag}_all", "all", None, list(pool), offset))
    return Fold(offset, hold, pool, k, sel.method, chosen, units)


# ------------------------------------------------------------------ what the folds say together
def per_view(results: dict, folds: list[Fold], method: str) -> dict[int, dict]:
    """{held-out camera index: its scores} of ``method`` over ``folds`` (``results``: unit key -> metrics):
    ``psnr``, ``ssim`` (random: the mean over the fold's draws), ``name``, ``fold``, ``unit`` (the unit whose
    render it is). A fold without that method gives nothing."""
    out: dict[int, dict] = {}
    for f in folds:
        us = [u for u in f.units if u.method == method and u.key in results]
        if not us:
            continue
        pvs = [results[u.key]["per_view"] for u in us]
        for j, cam in enumerate(f.holdout):
            out[cam] = {"name": pvs[0][j]["name"], "psnr": float(np.mean([p[j]["psnr"] for p in pvs])),
                        "ssim": float(np.mean([p[j]["ssim"] for p in pvs])), "fold": f.offset, "unit": us[0].key}
    return out


def summarize(results: dict, folds: list[Fold], level: float, margin: float, prior: tuple = KAPPA_PRIOR,
              rival_folds: dict | None = None, resolution: float = 0.0) -> tuple[dict, dict, float | None]:
    """(methods, paired, gap_closed) over the finished ``folds``.

    ``methods[m]``: held-out ``psnr`` / ``ssim`` (means over every held-out photo of the folds that trained
    it: ``n_views``; all photos train in the first :data:`ALL_FOLDS` only), ``per_view`` (:func:`per_view`, in
    camera order), ``n_train`` (the subsets' mean size), ``key`` (fold 0's unit, whose renders the report
    shows), ``units``; random also ``psnr_std`` over its draws' means. ``paired["selection-<rival>"]``:
    :func:`curate.core.stats.folds_moderated` of the per-view differences at ``level`` with ``prior``
    (``(kappa0, nu0)``; ``(1, 0)``: the folds alone, :func:`curate.core.stats.folds_paired`'s interval), with
    ``decision`` (:func:`curate.core.stats.decision` at ``margin`` and ``resolution``); ``rival_folds[rival]``:
    the number of leading folds its comparison uses (the look that decided it; default all). ``gap_closed``:
    (selection - random) / (all - random) over the same photos, None when all photos do not beat random subsets.
    """
    from curate.core.stats import decision, folds_moderated
    methods: dict[str, dict] = {}
    for m in ("selection", *RIVALS, "all"):
        pv = per_view(results, folds, m)
        if not pv:
            continue
        us = [results[u.key] for f in folds for u in f.units if u.method == m and u.key in results]
        first = next(u.key for f in folds for u in f.units if u.method == m and u.key in results)
        rows = [pv[c] for c in sorted(pv)]
        methods[m] = {"psnr": float(np.mean([r["psnr"] for r in rows])),
                      "ssim": float(np.mean([r["ssim"] for r in rows])), "per_view": rows,
                      "n_train": float(np.mean([u["n_train"] for u in us])), "key": first,
                      "units": len(us), "n_views": len(rows)}
        if m == "random":
            methods[m]["psnr_std"] = float(np.std([u["psnr"] for u in us], ddof=1)) if len(us) > 1 else 0.0
    paired = {}
    sel = per_view(results, folds, "selection")
    for r in RIVALS:
        other = per_view(results, folds, r)
        if not sel or not other:
            continue
        upto = folds[:(rival_folds or {}).get(r, len(folds))]
        diffs = [np.array([sel[c]["psnr"] - other[c]["psnr"] for c in f.holdout if c in sel and c in other])
                 for f in upto]
        p = folds_moderated(diffs, level, kappa0=prior[0], nu0=prior[1])
        if not p["n"]:
            continue
        paired[f"selection-{r}"] = {**_finite_or_none(p), "decision": decision(p, margin, resolution),
                                    "margin": margin, "resolution": resolution}
    gap = None
    if all(m in methods for m in ("selection", "random", "all")):
        rnd, al = per_view(results, folds, "random"), per_view(results, folds, "all")
        common = sorted(set(sel) & set(rnd) & set(al))                 # the same photos for all three
        s, r_, a = (float(np.mean([d[c]["psnr"] for c in common])) for d in (sel, rnd, al))
        if a - r_ > 1e-6:
            gap = (s - r_) / (a - r_)
    return methods, paired, gap


def _finite_or_none(p: dict) -> dict:
    """``p`` with its non-finite figures (the infinite interval of one held-out view) as None: no NaN or
    Infinity reaches summary.json."""
    return {k: (None if isinstance(v, float) and not np.isfinite(v) else v) for k, v in p.items()}


def folds_to_decide(p: dict, margin: float, max_folds: int, prior: tuple = KAPPA_PRIOR,
                    resolution: float = 0.0, power: float = 0.0) -> int | None:
    """The fewest folds at which the interval ``p`` (:func:`curate.core.stats.folds_moderated`'s, at its
    ``level``) is expected to decide (exclude 0, lie within ``margin``, or be at most ``resolution`` wide on each
    side: :func:`curate.core.stats.decision`) if its mean, the views' spread within
    folds and the folds' design effect stay as measured and every fold holds as many views as the mean so far;
    ``p["n_folds"]`` when it has decided; None when even ``max_folds`` would not (or ``p`` has no spread to
    project). ``power``: a margin of that many standard errors of the pooled mean beyond the interval's edge
    (0: the folds at which a mean that holds just decides, about an even chance; :data:`LAST_LOOK_POWER` for a
    rival's last look)."""
    import math

    from curate.core.stats import DECIDED, decision, moderated_variance, t_quantile
    F, N = int(p.get("n_folds") or 0), int(p.get("n") or 0)
    if F == 0 or N == 0:
        return None
    if decision(p, margin, resolution) in DECIDED:
        return F
    sw, m = p.get("sd_within"), abs(float(p["mean"]))
    if sw is None or not math.isfinite(sw):
        return None
    kappa0, nu0 = prior
    k_folds = p.get("kappa_folds")
    k_folds = kappa0 if k_folds is None else k_folds
    for g in range(F + 1, int(max_folds) + 1):
        n = N * g / F
        v0 = sw * sw / n
        var, dof = moderated_variance(v0, k_folds * v0, g, n - g, kappa0, nu0)
        se = math.sqrt(var) if var > 0 else 0.0
        half = t_quantile(0.5 + p["level"] / 2, dof) * se
        reach = half + power * se
        if reach < m or m + reach <= margin or half <= resolution:
            return g
    return None


def next_look(p: dict, margin: float, max_folds: int, resolution: float = 0.0, last: bool = False,
              prior: tuple = KAPPA_PRIOR) -> int | None:
    """The fold count of a rival's next look after the interval ``p``: :func:`folds_to_decide`'s even chance; for
    its ``last`` look, the folds at :data:`LAST_LOOK_POWER` (all ``max_folds`` where only they give an even
    chance). None: not even ``max_folds`` give an even chance (not pursued)."""
    even = folds_to_decide(p, margin, max_folds, prior, resolution)
    if not last or even is None:
        return even
    sure = folds_to_decide(p, margin, max_folds, prior, resolution, power=LAST_LOOK_POWER)
    return int(max_folds) if sure is None else sure


def plan_rivals(needs: dict[str, int | None], n_folds: int, fold_units: int, unit_s: float, workers: int,
                seconds_left: float, committed: dict[str, int] | None = None) -> tuple[list[str], int | None]:
    """Which undecided rivals to train on, each only to the folds its own comparison is projected to need: the
    rivals that need the fewest folds first (``needs``: :func:`folds_to_decide`), each taken while its trainings
    fit in ``seconds_left`` beside those already taken (a fold trains the selection, if any rival still needs it,
    and each rival that still needs it: ``fold_units`` trainings for random subsets (``--random-seeds``), one for
    the others; ``unit_s`` seconds a training, ``workers`` at a time). ``committed``: rivals already planned (to
    the fold count given) by an earlier look; their trainings are spent first, and the selection's trainings in
    those folds are shared. A rival whose own need does not fit is not taken, so a comparison that needs many
    folds does not eat the time that would decide the others. Returns (the rivals, the last fold count any of
    them needs; None: none fits)."""
    committed = dict(committed or {})

    def cost(plan: dict[str, int]) -> float:
        end = max(plan.values(), default=n_folds)
        return sum((1 if any(g <= x for x in plan.values()) else 0)
                   + sum(fold_units if r == "random" else 1 for r, x in plan.items() if g <= x)
                   for g in range(n_folds + 1, end + 1)) * unit_s / max(workers, 1)
    taken: list[str] = []
    for r in sorted((r for r in needs if needs[r] is not None), key=lambda r: needs[r]):
        trial = {**committed, **{x: needs[x] for x in taken + [r]}}
        if cost(trial) <= seconds_left:
            taken.append(r)
    return taken, (max(needs[x] for x in taken) if taken else None)


def decided(paired: dict) -> bool:
    """Every rival compared is decided: ahead, behind, level or resolved (none undecided)."""
    from curate.core.stats import DECIDED
    return bool(paired) and all(p.get("decision") in DECIDED for p in paired.values())


def curve_budgets(k: int, n_pool: int) -> list[int]:
    """The budgets a learning-curve fold trains around ``k`` (the law's advice at the fold's size): ``k`` and
    the check's about half and twice it (:func:`curate.evaluate.check.check_budgets`), within [3, n_pool - 2]."""
    from curate.evaluate.check import check_budgets
    return sorted(set(check_budgets(k, n_pool)) | ({k} if 3 <= k <= n_pool - 2 else set()))


def curve_fold(cfg: EvalConfig, select_cfg, cams, grid, k_law: int, offset: int) -> Fold:
    """Fold ``offset``'s learning curve (:mod:`curate.evaluate.budget`): the selection's method at
    :func:`curve_budgets` of the law's ``k_law`` scaled to the fold's pool (units ``f<offset>_curve_b<k>``,
    method 'check') and all photos left (``f<offset>_all``: the same unit as the evaluation's, reused by it)."""
    from curate.core.stats import holdout_split
    from curate.select.select import select
    from curate.select.visibility import build_pair_index
    select_cfg = whole_capture_method(select_cfg, cams)
    pool, hold = (v.tolist() for v in holdout_split(len(cams), cfg.holdout_every, offset))
    k = eval_budget(k_law, len(cams), len(pool))
    pc = cams[pool]
    index = build_pair_index(pc, grid.nodes(), select_cfg.energy.bins, device=select_cfg.device)
    tag = f"f{offset:02d}"
    units, method = [], ""
    for b in curve_budgets(k, len(pool)):
        sel = select(pc, grid, b, select_cfg, index=index)
        method = sel.method
        units.append(Unit(f"{tag}_curve_b{b}", "check", None, [pool[i] for i in sel.chosen], offset))
    units.append(Unit(f"{tag}_all", "all", None, list(pool), offset))
    return Fold(offset, hold, pool, k, method, [], units)


def curve_points(results: dict, folds: list[Fold]) -> list[dict]:
    """The learning curve's measured points: per budget (the i-th of each fold's :func:`curve_budgets`; ``k``
    their mean, of the folds' pools), the loss against all photos left, ``all - subset`` per held-out photo
    pooled over the folds (:func:`curate.core.stats.folds_paired`): ``k``, ``loss`` (dB), ``lo``, ``hi``, ``n``."""
    from curate.core.stats import folds_paired
    by_rank: dict[int, list] = {}
    for f in folds:
        al = next((u for u in f.units if u.method == "all" and u.key in results), None)
        if al is None:
            continue
        a = np.array([v["psnr"] for v in results[al.key]["per_view"]])
        for i, u in enumerate(u for u in f.units if u.method == "check"):
            if u.key in results:
                d = a - np.array([v["psnr"] for v in results[u.key]["per_view"]])
                by_rank.setdefault(i, []).append((len(u.subset), d))
    out = []
    for i in sorted(by_rank):
        p = _finite_or_none(folds_paired([d for _, d in by_rank[i]]))
        if p["mean"] is None:
            continue
        out.append({"k": int(round(np.mean([k for k, _ in by_rank[i]]))), "loss": p["mean"], "lo": p["lo"],
                    "hi": p["hi"], "n": p["n"]})
    return out
