"""View medoids: the subset whose views lie closest, on average, to the pool's views.

A held-out (or novel) view is rendered well when a training view sits near it: on real
captures, held-out PSNR tracks the distance from a held-out view to its nearest chosen
camera (issue 7). The held-out views of a capture come from the same path as the pool,
so the subset that minimises the *mean* distance from every pool view to its nearest
chosen view is what the test rewards: the k-medoids of the pool's views. Farthest-view
sampling (k-center) minimises the *largest* distance instead, and spends cameras on
outliers; the paper's energy looks at the scene's nodes, not at the views.

View distance (a metric, scale-covariant, no tuned weights)::

    d(i, j) = |c_i - c_j| + |a_i - a_j|,     a_i = c_i + D_i v_i

with c the camera centres, v the viewing directions and a_i the point the camera looks
at, D_i deep: the median depth of the scene nodes camera i observes (from the selection's
pair index). Two cameras side by side looking the same way are |dc| apart twice; one
camera turned by theta on the spot moves its look-at point by 2 D sin(theta / 2). A
camera that observes no node uses the median depth of all observations (or the
centres' spread when there are none).

Algorithm: farthest-point initialisation in ``d`` (deterministic: the first pick is the
view nearest the mean of the (c, a) embedding), then Voronoi iteration (assign every
pool view to its nearest medoid; move each medoid to the member with the least summed
distance to its cluster) until nothing moves. Each iteration lowers the summed distance
or stops, so it ends. ``initial`` cameras are fixed medoids. Memory is [K, B] for the
assignment and [m, m] per cluster, never [K, K].

Path weights (``MedoidsConfig.path_weights``): a video samples its path unevenly (the
walker lingers, speeds up; frames are dropped or held out), and the plain mean counts
frames. Weighing each view by the stretch of path it stands for (:func:`path_weights`)
makes the mean one along the path: a weighted k-medoids, same algorithm.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from curate.select.baselines import farthest_point
from curate.core.cameras import Cameras
from curate.select.methods import PATH_WEIGHTS, SHARPNESS_WEIGHT


@dataclass(frozen=True)
class MedoidsConfig:
    """Method "medoids": k-medoids of the pool's views."""

    depth: float | None = None
    """Look-at depth D in world units for every camera (None: each camera's median depth of
    the nodes it observes)."""
    max_iters: int = 100
    """Voronoi iterations at most (it usually stops in under 20)."""
    power: float = 1.0
    """Minimise the mean of ``d ** power``: 1 is k-medoids (the mean distance); larger values
    weigh far, badly covered views more, towards farthest-view sampling's largest distance."""

    energy_share: float = 0.0
    """Share of the budget chosen after the medoids by the paper's greedy energy, with the
    medoids as the initial set (method "medoids" in :func:`curate.select.select.select`): the
    medoids cover the path, the energy adds views that widen the directions each node is
    seen from (for views off the path). 0: medoids only."""

    sharpness_weight: float = SHARPNESS_WEIGHT
    """How much a blurry view is avoided as a medoid: a view whose image sharpness is
    ``r`` times the median of its nearest pool views counts as ``sharpness_weight * tau *
    -ln(r)`` farther from every view (``tau``: the pool's median distance from a view to its
    nearest other view; ``ln r`` clipped to [-1, 1]). 0: sharpness is ignored."""

    path_weights: bool = PATH_WEIGHTS
    """Weigh each pool view by the stretch of the capture path it stands for (half the view
    distance to the previous plus to the next view in name order, i.e. capture order for
    numbered video frames; capped at ``PATH_CAP`` times the median step, mean 1): the mean is
    then taken along the path, not over the frames, so a stretch sampled sparsely (a
    dropped frame, a fast walk) counts as much as one sampled densely (the walker
    lingering). Ignored (uniform weights, a warning) when the views are not in path order
    (:func:`path_weights`)."""

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sharpness_weight) and self.sharpness_weight >= 0):
            raise ValueError(f"sharpness_weight must be finite and >= 0, got {self.sharpness_weight}")
        if not (0.0 <= self.energy_share <= 1.0):
            raise ValueError(f"energy_share must be in [0, 1], got {self.energy_share}")
        if self.depth is not None and not (np.isfinite(self.depth) and self.depth > 0):
            raise ValueError(f"depth must be finite and > 0, got {self.depth}")
        if self.max_iters < 0:
            raise ValueError(f"max_iters must be >= 0, got {self.max_iters}")
        if not (np.isfinite(self.power) and self.power > 0):
            raise ValueError(f"power must be finite and > 0, got {self.power}")


def view_depths(cams: Cameras, nodes: np.ndarray | None, index=None) -> np.ndarray:
    """[K] look-at depth per camera: median distance to the nodes it observes (``index``
    pairs); cameras with none take the median over all pairs, or the centres' RMS spread."""
    K = len(cams)
    c = cams.centres
    spread = float(np.sqrt(np.mean(np.sum((c - c.mean(0)) ** 2, axis=1)))) if K else 0.0
    fallback = spread if spread > 0 else 1.0
    out = np.full(K, np.nan)
    if index is not None and nodes is not None and index.n_pairs > 0:
        node_of = np.repeat(np.arange(index.n_nodes), np.diff(index.indptr))      # [P]
        depth = np.linalg.norm(np.asarray(nodes, np.float64)[node_of] - c[index.cam.astype(np.int64)], axis=1)  # [P]
        for k in range(K):                                    # the index's camera-major view of its pairs
            seg = depth[index.cam_pos[index.cam_indptr[k]:index.cam_indptr[k + 1]]]
            if len(seg):
                out[k] = np.median(seg)
        fallback = float(np.median(depth)) if np.median(depth) > 0 else fallback
    out[~(out > 0)] = fallback
    return out


def embed(cams: Cameras, depths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centres [K, 3], look-at points [K, 3]) of the view distance."""
    c = cams.centres
    return c, c + np.asarray(depths, np.float64)[:, None] * cams.view_dirs


def view_distance(c: np.ndarray, a: np.ndarray, rows, cols) -> np.ndarray:
    """[len(rows), len(cols)] view distances between the embedded views ``rows`` and ``cols``."""
    rows, cols = np.asarray(rows, np.int64), np.asarray(cols, np.int64)
    dc = np.linalg.norm(c[rows][:, None] - c[cols][None], axis=2)
    da = np.linalg.norm(a[rows][:, None] - a[cols][None], axis=2)
    return dc + da


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


class PathOrderWarning(UserWarning):
    """Path weights were asked for, but the views are not in capture order: plain weights."""


PATH_CAP = 4.0
"""A step between consecutive views counts for at most this many median steps (a cut in
the video, a second sequence)."""
PATH_ORDER_MIN = 0.6
"""Views count as a path when at least this share of them has its previous or next view
among its two nearest views (:func:`path_order_share`; ``scripts/holdout_holes.py`` prints
it: 0.78-0.98 on the office, the synthetic room and the object sets)."""
PATH_ORDER_SAMPLE = 512
"""The share is measured on this many views, evenly spread in capture order (all of a
smaller pool): memory and time [512, K]."""


def path_order_share(c: np.ndarray, a: np.ndarray) -> float:
    """Share of the embedded views ``c``, ``a`` [K, 3] (K >= 3) whose previous or next view is
    among their two nearest views, measured on ``PATH_ORDER_SAMPLE`` views evenly spread in
    order (all of a smaller pool). Memory [512, K]."""
    K = len(c)
    rows = np.unique(np.linspace(0, K - 1, min(K, PATH_ORDER_SAMPLE)).astype(np.int64))   # [r] views tested
    d = view_distance(c, a, rows, np.arange(K))                   # [r, K]
    d[np.arange(len(rows)), rows] = np.inf
    d2 = np.partition(d, 1, axis=1)[:, 1]                         # [r] the second-nearest distance
    prev = np.where(rows > 0, d[np.arange(len(rows)), np.maximum(rows - 1, 0)], np.inf)
    nxt = np.where(rows < K - 1, d[np.arange(len(rows)), np.minimum(rows + 1, K - 1)], np.inf)
    return float(np.mean(np.minimum(prev, nxt) <= d2))


def path_weights(c: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """[K] weights, mean 1, of embedded views ``c``, ``a`` [K, 3] in capture order: half the
    view distance to the previous plus to the next view (a path end: its one step), each
    step capped at ``PATH_CAP`` median steps. None when the views do not form a path: fewer
    than 3, every step 0, or less than ``PATH_ORDER_MIN`` of the views with a neighbour in
    capture order among their two nearest views (:func:`path_order_share`). Memory [512, K]."""
    K = len(c)
    if K < 3:
        return None
    step = np.linalg.norm(c[1:] - c[:-1], axis=1) + np.linalg.norm(a[1:] - a[:-1], axis=1)   # [K-1]
    med = float(np.median(step))
    if not (np.isfinite(med) and med > 0):
        return None
    if path_order_share(c, a) < PATH_ORDER_MIN:
        return None
    step = np.minimum(step, PATH_CAP * med)
    w = np.empty(K)
    w[1:-1] = 0.5 * (step[:-1] + step[1:])
    w[0], w[-1] = step[0], step[-1]
    return w / w.mean()


def medoids_select(cams: Cameras, budget: int, cfg: MedoidsConfig = MedoidsConfig(), initial=(),
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
    c, a = embed(cams, depths)
    allk = np.arange(K)

    # farthest-point initialisation in the view distance, from the view nearest the mean (c, a)
    x = np.concatenate([c, a], axis=1)
    chosen = farthest_point(K, budget, lambda k: view_distance(c, a, [k], allk)[0],
                            int(np.argmin(np.linalg.norm(x - x.mean(0), axis=1))), initial)

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
