"""Pool coverage: choose the subset that best *represents* the pool's own views.

The objective is facility location over the pool (monotone submodular)::

    F(S) = sum_i w_i max_{j in S} sim(i, j)

Every pool camera i is a "client" that some chosen camera j must stand in for; sim(i, j)
in [0, 1] says how well view j can stand in for view i (sim(i, i) = 1). Greedy
maximisation keeps the (1 - 1/e) guarantee; it minimises the *mean* dissimilarity of
the pool views to the subset (what held-out PSNR tracks on a capture path), whereas
farthest-view sampling (k-center) minimises the *largest* one and the paper's energy
looks at the scene's nodes, not at the views.

Similarities (``CoverageConfig.similarity``):

* ``"cells"``: how much of what camera i observes camera j observes too, from the same
  direction: ``|C_i & C_j| / |C_i|`` over the (node, direction bin) cells of the
  :class:`curate.select.visibility.PairIndex` (the same frustum test and bins as the energy).
  It combines position, orientation and scene depth: two cameras a metre apart looking
  at a far wall overlap; at a near one they do not. A camera that observes no cell is
  represented by itself only (sim(i, i) = 1), so an empty node set degrades to an
  arbitrary (lowest-index) choice, never NaN.
* ``"pose"``: a Gaussian kernel on camera-centre distance and viewing-direction angle,
  ``exp(-d^2 / (2 s_d^2) - a^2 / (2 s_a^2))``; ``s_d`` defaults to the distance from a
  camera to its (K / budget)-th nearest pool neighbour (median over the pool): the
  radius each chosen camera must stand in for at this budget.
* ``"cells+pose"``: the mean of the two.

Both are kept sparse (entries below ``min_sim`` dropped), so pools of thousands fit.
The greedy is lazy (a heap of stale upper bounds, valid by submodularity) and exact:
it returns the same choices as the plain greedy of :func:`facility_location_bruteforce`,
ties (within 1e-11 relative) going to the lowest index.
"""

from __future__ import annotations

import heapq
import time
from dataclasses import dataclass, field

import numpy as np

from curate.core.cameras import Cameras
from curate.select.visibility import PairIndex

TIE_RTOL = 1e-11
SIMILARITIES = ("cells", "pose", "cells+pose")
OBJECTIVES = ("views", "cells")


@dataclass(frozen=True)
class CoverageConfig:
    """Facility-location selection over the pool's own views."""

    objective: str = "views"
    """"views": facility location over the pool's views (each pool view needs one chosen view
    that stands in for it, by ``similarity``); "cells": saturating coverage of the (node,
    direction-bin) cells weighted by how often the pool observes them (:func:`cell_coverage_greedy`)."""
    cell_views: int = 2
    """"cells": views of a cell after which it counts fully (T)."""
    cell_power: float = 1.0
    """"cells": a cell's weight is (pool views observing it) ** cell_power (0: every observed cell alike)."""
    similarity: str = "cells+pose"
    """"views": "cells" (overlap of observed (node, direction-bin) cells), "pose" (centre distance and
    viewing angle kernel) or "cells+pose" (their mean)."""
    pos_scale: float | None = None
    """"pose": centre-distance scale s_d in world units (None: from the pool's spacing and the budget)."""
    angle_scale_deg: float = 30.0
    """"pose": viewing-angle scale s_a (degrees)."""
    min_sim: float = 1e-3
    """Similarities below this are dropped (sparsity)."""

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {OBJECTIVES}, got {self.objective!r}")
        if self.cell_views < 1:
            raise ValueError(f"cell_views must be >= 1, got {self.cell_views}")
        if not (self.cell_power >= 0 and np.isfinite(self.cell_power)):
            raise ValueError(f"cell_power must be finite and >= 0, got {self.cell_power}")
        if self.similarity not in SIMILARITIES:
            raise ValueError(f"similarity must be one of {SIMILARITIES}, got {self.similarity!r}")
        if self.pos_scale is not None and not self.pos_scale > 0:
            raise ValueError(f"pos_scale must be > 0, got {self.pos_scale}")
        if not self.angle_scale_deg > 0:
            raise ValueError(f"angle_scale_deg must be > 0, got {self.angle_scale_deg}")
        if not 0 <= self.min_sim < 1:
            raise ValueError(f"min_sim must be in [0, 1), got {self.min_sim}")


# --------------------------------------------------------------------- similarities
def _sparse():
    import scipy.sparse as sp
    return sp


def cell_similarity(index: PairIndex, min_sim: float = 1e-3):
    """scipy CSC [K, K]: ``S[i, j] = |C_i & C_j| / |C_i|`` (row i: the client view), diagonal 1."""
    sp = _sparse()
    K = index.n_cams
    if index.n_pairs == 0 or K == 0:
        return sp.identity(K, format="csc", dtype=np.float64)
    cols = index.nb.astype(np.int64)
    A = sp.csr_matrix((np.ones(index.n_pairs, np.float32), (index.cam.astype(np.int64), cols)),
                      shape=(K, index.n_nodes * index.n_bins))
    O = (A @ A.T).tocoo()                            # shared cells (exact small integers in float32)
    cnt = np.asarray(A.sum(1)).ravel().astype(np.float64)
    val = O.data.astype(np.float64) / np.maximum(cnt[O.row], 1.0)
    keep = (val >= min_sim) & (O.row != O.col)
    S = sp.csc_matrix((val[keep], (O.row[keep], O.col[keep])), shape=(K, K))
    return (S + sp.identity(K, format="csc")).tocsc()


def default_pos_scale(cams: Cameras, budget: int) -> float:
    """Median distance from a pool camera to its ceil(K / budget)-th nearest neighbour (> 0)."""
    from scipy.spatial import cKDTree
    K = len(cams)
    if K < 2:
        return 1.0
    k = int(min(K - 1, max(1, np.ceil(K / max(budget, 1)))))
    d, _ = cKDTree(cams.centres).query(cams.centres, k=k + 1)
    s = float(np.median(np.atleast_2d(d)[:, k]))
    if not s > 0:
        ext = float(np.linalg.norm(np.ptp(cams.centres, axis=0)))
        s = ext / max(budget, 1) if ext > 0 else 1.0
    return s


def pose_similarity(cams: Cameras, pos_scale: float, angle_scale_deg: float = 30.0, min_sim: float = 1e-3):
    """scipy CSC [K, K] Gaussian kernel on centre distance and viewing angle (symmetric, diagonal 1)."""
    from scipy.spatial import cKDTree
    sp = _sparse()
    K = len(cams)
    if K == 0:
        return sp.csc_matrix((0, 0))
    c, d = cams.centres, cams.view_dirs
    cut = -2.0 * np.log(max(min_sim, 1e-12))         # exponent bound for the distance part alone
    radius = pos_scale * np.sqrt(cut)
    pairs = cKDTree(c).query_pairs(radius, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    dist2 = np.sum((c[i] - c[j]) ** 2, axis=1) / pos_scale ** 2
    ang = np.arccos(np.clip(np.sum(d[i] * d[j], axis=1), -1.0, 1.0)) / np.radians(angle_scale_deg)
    val = np.exp(-0.5 * (dist2 + ang ** 2))
    keep = val >= min_sim
    i, j, val = i[keep], j[keep], val[keep]
    S = sp.csc_matrix((np.r_[val, val], (np.r_[i, j], np.r_[j, i])), shape=(K, K))
    return (S + sp.identity(K, format="csc")).tocsc()


def similarity(cfg: CoverageConfig, cams: Cameras, index: PairIndex | None, budget: int):
    """The [K, K] similarity of ``cfg`` (CSC, rows = clients, columns = facilities)."""
    parts = []
    if cfg.similarity in ("cells", "cells+pose"):
        if index is None:
            raise ValueError("the 'cells' similarity needs the pair index")
        parts.append(cell_similarity(index, cfg.min_sim))
    if cfg.similarity in ("pose", "cells+pose"):
        s = cfg.pos_scale if cfg.pos_scale is not None else default_pos_scale(cams, budget)
        parts.append(pose_similarity(cams, s, cfg.angle_scale_deg, cfg.min_sim))
    S = parts[0] if len(parts) == 1 else (parts[0] + parts[1]) * 0.5
    return S.tocsc()


# --------------------------------------------------------------------- greedy
@dataclass
class CoverageTrace:
    """What the facility-location greedy did: choices, F after each step, step times, evaluations."""

    chosen: list[int] = field(default_factory=list)
    objective: list[float] = field(default_factory=list)
    step_seconds: list[float] = field(default_factory=list)
    evaluations: int = 0


def _column(S, j: int) -> tuple[np.ndarray, np.ndarray]:
    a, b = S.indptr[j], S.indptr[j + 1]
    return S.indices[a:b], S.data[a:b]


def lazy_greedy(n: int, gain, take, budget: int, taken: np.ndarray | None = None, value: float = 0.0) -> CoverageTrace:
    """Lazy greedy for a monotone submodular F over ``n`` candidates.

    ``gain(j)`` -> F(S + j) - F(S) at the current S; ``take(j)`` adds j to S. Stale gains
    are upper bounds (submodularity), so only candidates whose bound could still win are
    re-evaluated. Exact: near-ties (TIE_RTOL relative to F) go to the lowest index, as in
    a plain greedy.
    """
    taken = np.zeros(n, bool) if taken is None else taken
    tr = CoverageTrace()
    budget = int(min(max(0, budget), n - int(taken.sum())))
    if budget == 0:
        return tr
    heap = [(-gain(j), j) for j in range(n) if not taken[j]]
    tr.evaluations += len(heap)
    heapq.heapify(heap)
    while len(tr.chosen) < budget and heap:
        t0 = time.perf_counter()
        fresh: dict[int, float] = {}
        while True:
            if taken[heap[0][1]]:
                heapq.heappop(heap)
                continue
            j = heap[0][1]
            if j in fresh:   # the best bound is a fresh value: nothing stale can beat it
                break
            g = gain(j)
            heapq.heapreplace(heap, (-g, j))
            fresh[j] = g
            tr.evaluations += 1
        best = -heap[0][0]
        tol = TIE_RTOL * max(1.0, abs(value + best))   # relative to F, as in the plain greedy
        # Near-ties: every candidate whose (stale, upper) bound reaches best - tol is made
        # fresh, so the lowest index among the true near-best wins, as in the plain greedy.
        stale = [k for b, k in heap if -b >= best - tol and k not in fresh and not taken[k]]
        if stale:
            for k in stale:
                fresh[k] = gain(k)
            tr.evaluations += len(stale)
            heap = [(-fresh[k], k) if k in fresh else (b, k) for b, k in heap if not taken[k]]
            heapq.heapify(heap)
            best = max(fresh.values())
        j = min(k for k, g in fresh.items() if g >= best - tol)
        take(j)
        taken[j] = True
        value += fresh[j]
        tr.chosen.append(j)
        tr.objective.append(value)
        tr.step_seconds.append(time.perf_counter() - t0)
    return tr


def facility_location_greedy(S, budget: int, weights=None, initial=()) -> CoverageTrace:
    """Lazy greedy maximisation of ``F(S) = sum_i w_i max_{j in S} S[i, j]`` (S: CSC [K, K], >= 0).

    Adds ``budget`` columns (fewer if the pool runs out) to ``initial``; the same choices
    as the plain greedy (:func:`facility_location_bruteforce`). A gain costs O(entries of
    the candidate's column).
    """
    S = S.tocsc()
    S.sort_indices()
    K = S.shape[1]
    w = np.ones(K) if weights is None else np.asarray(weights, np.float64)
    cur = np.zeros(K)
    taken = np.zeros(K, bool)

    def gain(j: int) -> float:
        rows, vals = _column(S, j)
        return float(np.dot(w[rows], np.maximum(vals - cur[rows], 0.0)))

    def take(j: int) -> None:
        rows, vals = _column(S, j)   # CSC rows of a column are distinct
        cur[rows] = np.maximum(cur[rows], vals)

    for j in dict.fromkeys(int(k) for k in initial):
        take(j)
        taken[j] = True
    return lazy_greedy(K, gain, take, budget, taken, float(np.dot(w, cur)))


# --------------------------------------------------------------------- cell coverage
def cell_weights(index: PairIndex, power: float = 1.0) -> np.ndarray:
    """[M * B] weight of each (node, direction-bin) cell: (pool cameras observing it) ** power."""
    from curate.select.visibility import chunked_bincount
    n = chunked_bincount(index.nb, index.n_nodes * index.n_bins).astype(np.float64)
    return n ** power if power != 1.0 else n


def camera_cells(index: PairIndex, k: int) -> np.ndarray:
    """The flat (node, bin) cells camera ``k`` observes (distinct)."""
    return index.nb[index.cam_pos[index.cam_indptr[k]:index.cam_indptr[k + 1]]].astype(np.int64)


def cell_coverage_greedy(index: PairIndex, budget: int, views: int = 2, power: float = 1.0,
                         initial=()) -> CoverageTrace:
    """Lazy greedy on ``F(S) = sum_c w_c min(n_S(c), T) / T`` over the (node, bin) cells c.

    ``n_S(c)``: chosen cameras observing cell c; ``T = views``; ``w_c``: the pool's own
    observations of c (``** power``), so cells the pool looks at often (where test views
    will look) count most, and a cell counts fully once T chosen views see it from that
    direction. Monotone submodular (a concave function of counts).
    """
    if views < 1:
        raise ValueError(f"views must be >= 1, got {views}")
    K = index.n_cams
    w = cell_weights(index, power)
    n = np.zeros(w.size, np.int32)
    taken = np.zeros(K, bool)

    def gain(j: int) -> float:
        c = camera_cells(index, j)
        return float(w[c][n[c] < views].sum()) / views

    def take(j: int) -> None:
        n[camera_cells(index, j)] += 1

    value = 0.0
    for j in dict.fromkeys(int(k) for k in initial):
        value += gain(j)
        take(j)
        taken[j] = True
    return lazy_greedy(K, gain, take, budget, taken, value)


def cell_coverage_value(index: PairIndex, subset, views: int = 2, power: float = 1.0) -> float:
    """F of :func:`cell_coverage_greedy` for ``subset``, from scratch."""
    w = cell_weights(index, power)
    n = np.zeros(w.size, np.int64)
    for k in subset:
        n[camera_cells(index, int(k))] += 1
    return float(np.sum(w * np.minimum(n, views)) / views)


def facility_location_value(S, subset, weights=None) -> float:
    """F(subset) from scratch (0 for the empty set)."""
    S = S.tocsc()
    K = S.shape[0]
    w = np.ones(K) if weights is None else np.asarray(weights, np.float64)
    subset = list(subset)
    if not subset:
        return 0.0
    return float(np.dot(w, S[:, subset].toarray().max(1)))


def facility_location_bruteforce(S, budget: int, weights=None, initial=()) -> list[int]:
    """Plain greedy reference: F recomputed from scratch for every candidate at every step."""
    D = np.asarray(S.toarray() if hasattr(S, "toarray") else S, np.float64)
    K = D.shape[1]
    w = np.ones(K) if weights is None else np.asarray(weights, np.float64)
    chosen: list[int] = []
    base = list(dict.fromkeys(int(k) for k in initial))
    budget = min(max(0, int(budget)), K - len(base))
    for _ in range(budget):
        cur = base + chosen
        scores = np.full(K, -np.inf)
        for j in range(K):
            if j in cur:
                continue
            scores[j] = float(np.dot(w, D[:, cur + [j]].max(1)))
        best = scores.max()
        tol = TIE_RTOL * max(1.0, abs(best))
        chosen.append(int(np.flatnonzero(scores >= best - tol)[0]))
    return chosen


def all_gains(S, cur: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """[K] facility-location gain of every column at the current coverage ``cur`` (one pass over S)."""
    S = S.tocsc()
    col = np.repeat(np.arange(S.shape[1]), np.diff(S.indptr))
    g = np.maximum(S.data - cur[S.indices], 0.0) * weights[S.indices]
    return np.bincount(col, weights=g, minlength=S.shape[1])


def coverage_select(cams: Cameras, index: PairIndex | None, budget: int, cfg: CoverageConfig = CoverageConfig(),
                    initial=(), weights=None, energy=None, energy_weight: float = 0.5) -> tuple[list[int], list[float]]:
    """Choose ``budget`` more pool cameras (fewer if it runs out) by ``cfg``'s coverage objective.

    Args:
        cams: the pool; index: its pair index (needed by the cell objective and similarities, and ``energy``).
        weights: [K] client weights of the "views" objective (None: 1 each).
        energy: an :class:`curate.select.energy.EnergyConfig` to add the paper's energy as a second
            term (each step maximises ``dF / F(pool) + energy_weight * dE / E(pool)``; a plain,
            non-lazy greedy, the energy not being submodular); None: coverage alone (lazy greedy).
    Returns:
        (chosen pool indices in order, F after each step).
    """
    K = len(cams)
    initial = [int(k) for k in dict.fromkeys(initial)]
    budget = int(min(max(0, budget), K - len(initial)))
    if budget <= 0:
        return [], []
    if cfg.objective == "cells" and index is None:
        raise ValueError("the 'cells' objective needs the pair index")
    if energy is None:
        if cfg.objective == "cells":
            tr = cell_coverage_greedy(index, budget, cfg.cell_views, cfg.cell_power, initial)
        else:
            S = similarity(cfg, cams, index, budget + len(initial))
            tr = facility_location_greedy(S, budget, weights, initial)
        return tr.chosen, tr.objective
    from curate.select.energy import energy_of_subset
    from curate.select.greedy import GreedyState, argmax_lowest
    from curate.select.visibility import chunked_bincount
    if cfg.objective == "cells":
        T = cfg.cell_views
        wc = cell_weights(index, cfg.cell_power)
        n = np.zeros(wc.size, np.int32)
        f_pool = cell_coverage_value(index, range(K), T, cfg.cell_power)

        def gains():
            return chunked_bincount(index.cam, K, lambda s, e: wc[index.nb[s:e]] * (n[index.nb[s:e]] < T)) / T

        def take(k):
            n[camera_cells(index, k)] += 1

        def value():
            return float(np.sum(wc * np.minimum(n, T)) / T)
    else:
        S = similarity(cfg, cams, index, budget + len(initial))
        w = np.ones(K) if weights is None else np.asarray(weights, np.float64)
        f_pool = float(w.sum())
        cur = np.zeros(K)

        def gains():
            return all_gains(S, cur, w)

        def take(k):
            rows, vals = _column(S, k)
            cur[rows] = np.maximum(cur[rows], vals)

        def value():
            return float(np.dot(w, cur))
    f_pool = f_pool if f_pool > 0 else 1.0
    e_pool = float(energy_of_subset(index, list(range(K)), energy).energy)
    e_pool = e_pool if e_pool > 0 else 1.0
    st = GreedyState(index, energy)
    for k in initial:
        st.add(k)
        take(k)
    chosen, obj = [], []
    for _ in range(budget):
        score = gains() / f_pool + energy_weight * (st.scores() - st.energy()[0]) / e_pool
        k = argmax_lowest(score, ~st.taken)
        if k < 0:
            break
        st.add(k)
        take(k)
        chosen.append(k)
        obj.append(value())
    return chosen, obj
