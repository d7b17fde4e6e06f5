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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .baselines import farthest_point
from .cameras import Cameras


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
    medoids as the initial set (method "medoids" in :func:`curate.select.select`): the
    medoids cover the path, the energy adds views that widen the directions each node is
    seen from (for views off the path). 0: medoids only."""

    def __post_init__(self) -> None:
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


def medoids_select(cams: Cameras, budget: int, cfg: MedoidsConfig = MedoidsConfig(), initial=(),
                   nodes: np.ndarray | None = None, index=None) -> tuple[list[int], list[float]]:
    """Choose ``budget`` more pool views (k-medoids with ``initial`` fixed).

    Returns (chosen, cost): chosen in the order of their farthest-point initialisation,
    cost the mean (view distance ** ``cfg.power``) from a pool view to its nearest medoid
    after each Voronoi iteration (the first entry: after initialisation).
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

    # Voronoi iteration; medoids 0..len(initial)-1 are fixed
    med = np.array(initial + chosen, np.int64)
    n_fixed = len(initial)
    costs = []
    for _ in range(cfg.max_iters + 1):
        D = np.empty((K, len(med)))
        for s in range(0, K, 2048):                               # [K, B] in chunks
            D[s:s + 2048] = view_distance(c, a, allk[s:s + 2048], med)
        assign = np.argmin(D, axis=1)                             # ties: the earlier medoid
        costs.append(float((D[allk, assign] ** cfg.power).mean()))
        if len(costs) > cfg.max_iters:
            break
        moved = False
        for j in range(n_fixed, len(med)):
            members = np.flatnonzero(assign == j)
            others = np.delete(med, j)
            members = members[~np.isin(members, others)]      # exact duplicates of another medoid
            if len(members) <= 1:
                continue
            tot = (view_distance(c, a, members, members) ** cfg.power).sum(1)   # [m]
            best = members[int(np.argmin(tot))]                  # ties: the lowest index
            cur = tot[np.searchsorted(members, med[j])] if med[j] in members else np.inf
            if tot.min() < cur - 1e-12 * abs(cur):
                med[j] = best
                moved = True
        if not moved:
            break
    return [int(k) for k in med[n_fixed:]], costs
