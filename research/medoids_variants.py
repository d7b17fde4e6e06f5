"""View medoids with the knobs that were measured and not adopted (docs/investigations/selection.md).

The product's :func:`curate.select.medoids.medoids_select` is the adopted k-medoids (mean view
distance, path weights). The variants the harness measured against it live here: a cost power
(``power``: 2 and 0.5 towards k-center / k-median of sqrt; 0.25 picks frames beside the hold-out's
holes), a share of the budget added by the paper's energy (``energy_share``), a prior that avoids
blurred frames (``sharpness_weight``), and explicit per-view weights (``weights``). This is the
code that produced those figures, kept so they can be reproduced.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from curate.core.cameras import Cameras
from curate.select.baselines import farthest_point
from curate.select.medoids import (PathOrderWarning, central_view, embed, path_weights, view_depths,
                                  view_distance)


@dataclass(frozen=True)
class MedoidsVariantConfig:
    """View medoids with the knobs of the measured variants."""

    depth: float | None = None
    """Look-at depth D in world units for every camera (None: each camera's median node depth)."""
    max_iters: int = 100
    """Voronoi iterations at most."""
    power: float = 1.0
    """Minimise the mean of ``d ** power``: 1 is k-medoids; larger weighs far views more."""
    energy_share: float = 0.0
    """Share of the budget chosen after the medoids by the paper's greedy energy."""
    sharpness_weight: float = 0.0
    """How much a view blurrier than its nearest views is avoided as a medoid (0: ignored)."""
    path_weights: bool = True
    """Weigh each view by the stretch of the capture path it stands for."""
    look_scale: float = 1.0
    """Scale of every camera's look-at depth (below 1: turning counts for less than walking)."""
    init: str = "fps"
    """Where the Voronoi iteration starts: "fps" (farthest-point order in the view distance, the
    product's) or "stride" (every n-th frame in capture order)."""
    stride_share: float = 0.0
    """Share of the budget taken first as every n-th frame (``stride``), the rest by the medoids
    with those frames fixed: a hedge between covering the capture by time and by view."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sharpness_weight) and self.sharpness_weight >= 0):
            raise ValueError(f"sharpness_weight must be finite and >= 0, got {self.sharpness_weight}")
        if not (0.0 <= self.energy_share <= 1.0):
            raise ValueError(f"energy_share must be in [0, 1], got {self.energy_share}")
        if not (np.isfinite(self.look_scale) and self.look_scale > 0):
            raise ValueError(f"look_scale must be finite and > 0, got {self.look_scale}")
        if self.init not in ("fps", "stride"):
            raise ValueError(f"init must be 'fps' or 'stride', got {self.init!r}")
        if not (0.0 <= self.stride_share <= 1.0):
            raise ValueError(f"stride_share must be in [0, 1], got {self.stride_share}")
        if not (np.isfinite(self.power) and self.power > 0):
            raise ValueError(f"power must be finite and > 0, got {self.power}")


SHARP_NEIGHBOURS = 6
"""A view's sharpness is compared with the median over itself and this many nearest views."""


def blur_penalty(c: np.ndarray, a: np.ndarray, sharp,
                 neighbours: int = SHARP_NEIGHBOURS) -> tuple[np.ndarray, float, np.ndarray]:
    """Blur penalty of embedded views ``c``, ``a`` [K, 3] with image sharpness ``sharp`` [K].

    Returns (penalty [K], tau, nearest [K, k]). penalty_i = -clip(ln(s_i / m_i), -1, 1), m_i
    the median sharpness of view i and its ``k = min(neighbours, K - 1)`` nearest views (view
    distance, listed in ``nearest``): a frame is compared with frames of the same content (a
    blurred video frame with its sharp neighbours), not textured walls with plain ones. A
    view whose sharpness is missing, non-finite or not positive (unreadable, flat) gets the
    full penalty 1 when its neighbours have usable values, 0 when none has. tau: the median
    distance from a view to its nearest other view (0 when every view coincides). Memory [1024, K]."""
    K = len(c)
    s = np.asarray(sharp, np.float64).reshape(-1)
    if len(s) != K:
        raise ValueError(f"sharpness has {len(s)} entries for {K} views")
    pen, nearest = np.zeros(K), np.zeros(K)
    k = max(0, min(int(neighbours), K - 1))
    nbrs = np.zeros((K, k), np.int64)
    if K < 2 or k == 0:
        return pen, 0.0, nbrs
    allk = np.arange(K)
    tiny = np.finfo(np.float64).tiny
    ok = np.isfinite(s) & (s > 0)
    for lo in range(0, K, 1024):
        rows = allk[lo:lo + 1024]
        d = view_distance(c, a, rows, allk)                    # [r, K]
        d[np.arange(len(rows)), rows] = np.inf
        nn = np.argpartition(d, k - 1, axis=1)[:, :k]          # [r, k]
        nbrs[rows] = nn
        nearest[rows] = d[np.arange(len(rows)), nn.T].min(0)
        grp_idx = np.c_[rows[:, None], nn]                      # [r, 1 + k]: the view and its nearest
        grp = np.where(ok[grp_idx], s[grp_idx], np.nan)
        with warnings.catch_warnings():                          # all-NaN groups give NaN: handled below
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(grp, axis=1)
        both = ok[rows] & np.isfinite(med)
        lr = np.zeros(len(rows))
        lr[both] = np.log(s[rows][both] / np.maximum(med[both], tiny))
        lr[~ok[rows] & np.isfinite(med)] = -1.0                # an unusable image next to usable ones
        pen[rows] = -np.clip(lr, -1.0, 1.0)
    tau = float(np.median(nearest))
    if not tau > 0:
        pos = nearest[nearest > 0]
        tau = float(pos.mean()) if len(pos) else 0.0
    return pen, tau, nbrs


def medoids_select(cams: Cameras, budget: int, cfg: MedoidsVariantConfig = MedoidsVariantConfig(), initial=(),
                   nodes: np.ndarray | None = None, index=None, sharpness=None,
                   weights=None) -> tuple[list[int], list[float]]:
    """Choose ``budget`` more pool views (k-medoids with ``initial`` fixed).

    ``sharpness`` [K] (image sharpness, e.g. :func:`curate.sfm.quality.sharpness`) is used when
    ``cfg.sharpness_weight`` > 0: a medoid m then costs ``d(i, m) ** power + off_m`` for each
    view i it serves, ``off_m = sharpness_weight * tau ** power * blur_penalty_m``
    (:func:`blur_penalty`), so a blurred frame gives way to a sharp neighbour. A medoid may
    then also move to one of its nearest views outside its cluster, and one that serves no
    view moves to the view whose cost it lowers most.

    With ``cfg.path_weights`` each view's cost is weighted by :func:`path_weights` (the
    cameras in capture order): a weighted k-medoids. ``weights`` [K] (finite, >= 0, not all
    0) gives the weights instead.

    Returns (chosen, cost): chosen in the order of their farthest-point initialisation,
    cost the (weighted) mean of that per-view cost (view distance ** ``cfg.power`` when sharpness is
    ignored) from a pool view to its medoid after each Voronoi iteration (the first entry:
    after initialisation).
    """
    K = len(cams)
    initial = [int(k) for k in dict.fromkeys(initial)]
    budget = min(max(0, int(budget)), K - len(initial))
    if budget <= 0:
        return [], []
    depths = (np.full(K, cfg.depth) if cfg.depth is not None else view_depths(cams, nodes, index))
    c, a = embed(cams, cfg.look_scale * depths)
    allk = np.arange(K)

    # farthest-point initialisation in the view distance, from the view nearest the mean (c, a)
    if cfg.init == "stride":
        from curate.select.baselines import stride_subset
        chosen = stride_subset(K, budget, initial)
    else:
        chosen = farthest_point(K, budget, lambda k: view_distance(c, a, [k], allk)[0], central_view(c, a), initial)

    off, nbrs = np.zeros(K), None                                 # [K] per-medoid cost offset
    if cfg.sharpness_weight > 0 and sharpness is not None:
        pen, tau, nbrs = blur_penalty(c, a, sharpness)
        off = cfg.sharpness_weight * tau ** cfg.power * pen
        if not np.any(off):
            nbrs = None

    w = np.ones(K)                                                # [K] weight of each view's cost
    if weights is not None:
        w = np.asarray(weights, np.float64).reshape(-1)
        if len(w) != K or not np.all(np.isfinite(w) & (w >= 0)) or not w.sum() > 0:
            raise ValueError(f"weights must be {K} finite values >= 0, not all 0")
        w = w / w.mean()
    elif cfg.path_weights:
        pw = path_weights(c, a)
        if pw is None:
            warnings.warn("medoids: the views are not in capture order (or too few); path weights ignored",
                          PathOrderWarning)
        else:
            w = pw

    # Voronoi iteration; medoids 0..len(initial)-1 are fixed
    med = np.array(initial + chosen, np.int64)
    n_fixed = len(initial)
    costs = []
    for _ in range(cfg.max_iters + 1):
        D = np.empty((K, len(med)))
        for s in range(0, K, 2048):                               # [K, B] in chunks
            D[s:s + 2048] = view_distance(c, a, allk[s:s + 2048], med) ** cfg.power + off[med]
        assign = np.argmin(D, axis=1)                             # ties: the earlier medoid
        costs.append(float((w * D[allk, assign]).mean()))
        if len(costs) > cfg.max_iters:
            break
        moved = False
        for j in range(n_fixed, len(med)):
            served = np.flatnonzero(assign == j)                 # the views medoid j serves
            if len(served) == 0:
                if nbrs is not None:                             # a blurred medoid nobody wants: move
                    gain = np.where(np.isin(allk, med), -np.inf, w * (D[allk, assign] - off))   # to the view
                    if gain.max() > 1e-12 * max(1.0, abs(costs[-1])):                  # that gains most
                        med[j] = int(np.argmax(gain))
                        moved = True
                continue
            cand = served if nbrs is None else np.union1d(served, nbrs[med[j]])   # with sharpness: the
            cand = cand[~np.isin(cand, np.delete(med, j))]       # medoid's nearest views too; never another medoid
            if len(cand) == 0:
                continue
            ws = w[served]                                       # [s]
            tot = ((view_distance(c, a, cand, served) ** cfg.power) @ ws
                   + ws.sum() * off[cand])                       # [m] cluster cost with each as medoid
            cur = float((view_distance(c, a, [med[j]], served)[0] ** cfg.power) @ ws + ws.sum() * off[med[j]])
            if tot.min() < cur - 1e-12 * abs(cur):
                med[j] = cand[int(np.argmin(tot))]               # ties: the lowest index
                moved = True
        if not moved:
            break
    return [int(k) for k in med[n_fixed:]], costs
