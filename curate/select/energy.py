"""The energy of Kopanas & Drettakis 2023 over a grid of nodes.

For a set C of N cameras and nodes p::

    E(C) = sum_p (1 - TV(f_p, u)) + O_f(p) ** gamma

* ``O_f(p) = n_p / N``, ``n_p`` the number of cameras of C observing p (see
  :mod:`curate.select.visibility`); ``O_f(p) ** gamma`` is taken as 0 when ``n_p = 0``, for
  every ``gamma >= 0``, and the frequency term is 0 for ``N = 0``.
* ``f_p`` is the normalised histogram of the directions from p to the centres of the
  cameras observing it (:mod:`curate.select.bins`), ``u`` the uniform distribution's share of
  each bin, ``TV = 1/2 sum_b |f_p(b) - u(b)|`` in [0, 1]; ``TV = 1`` for a node that no
  camera observes, so it adds nothing.

In words: each node scores up to 2. Up to 1 for being seen from directions spread
evenly over the sphere (a node seen from one side only scores its bin's uniform share,
a few percent), and up to 1 for being seen by a large fraction of the cameras; with the
default gamma = 0.05 the second term is nearly 1 as soon as a node is seen at all
(``(1/200) ** 0.05 = 0.77``), so it mostly rewards coverage.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from curate.core.cameras import Cameras
from curate.select.visibility import PairIndex, Visibility, build_pair_index, frustum_visible_reference
from curate.select.config import EnergyConfig, GAMMA_MAX  # noqa: F401  (their home: the config)


@dataclass
class EnergyTerms:
    """An energy value with its parts.

    Attributes:
        energy: angular + frequency.
        angular: sum over nodes of (1 - TV).
        frequency: sum over nodes of O_f ** gamma.
        n_cameras, n_nodes: N and the number of (active) nodes.
        angular_per_node: [M] 1 - TV per node (when asked for).
        frequency_per_node: [M] O_f ** gamma per node (when asked for).
        views_per_node: [M] n_p per node (when asked for).
    """

    energy: float
    angular: float
    frequency: float
    n_cameras: int
    n_nodes: int
    angular_per_node: np.ndarray | None = field(default=None, repr=False)
    frequency_per_node: np.ndarray | None = field(default=None, repr=False)
    views_per_node: np.ndarray | None = field(default=None, repr=False)

    def summary(self) -> dict:
        return {"energy": self.energy, "angular": self.angular, "frequency": self.frequency,
                "n_cameras": self.n_cameras, "n_nodes": self.n_nodes}


def pow_gamma(n: np.ndarray, gamma: float) -> np.ndarray:
    """``n ** gamma`` for counts n >= 0, with 0 where n == 0 (also for gamma == 0)."""
    n = np.asarray(n, np.float64)
    out = np.zeros_like(n)
    np.power(n, gamma, out=out, where=n > 0)
    return out


def total_variation(hist: np.ndarray, n: np.ndarray, shares: np.ndarray) -> np.ndarray:
    """TV between each node's normalised histogram and the uniform shares.

    Args:
        hist: [M, B] counts per bin.
        n: [M] counts per node (the rows' sums).
        shares: [B] uniform distribution (sums to 1).
    Returns:
        [M] TV in [0, 1]; 1 where n == 0.
    """
    n = np.asarray(n, np.float64)
    seen = n > 0
    tv = np.ones(n.shape[0])
    if np.any(seen):
        dev = np.abs(hist[seen] - n[seen, None] * shares[None, :]).sum(1)
        tv[seen] = np.clip(0.5 * dev / n[seen], 0.0, 1.0)
    return tv


def energy_from_hist(hist: np.ndarray, n_cams: int, cfg: EnergyConfig, per_node: bool = False) -> EnergyTerms:
    """Energy from per-node direction histograms [M, B] of a set of ``n_cams`` cameras."""
    hist = np.asarray(hist)
    n = hist.sum(1)
    tv = total_variation(hist, n, cfg.bins.shares())
    ang = 1.0 - tv
    freq = pow_gamma(n, cfg.gamma) / (float(n_cams) ** cfg.gamma) if n_cams > 0 else np.zeros(n.shape[0])
    return EnergyTerms(float(ang.sum() + freq.sum()), float(ang.sum()), float(freq.sum()), int(n_cams),
                       int(hist.shape[0]), ang if per_node else None, freq if per_node else None,
                       n.astype(np.int64) if per_node else None)


def histogram(index: PairIndex, cams: np.ndarray | None = None) -> np.ndarray:
    """[M, B] int64 direction histogram of the cameras ``cams`` (indices; all when None)."""
    if cams is None:
        cells = index.nb
    else:
        cams = np.asarray(cams, np.int64)
        if cams.size == 0:
            return np.zeros((index.n_nodes, index.n_bins), np.int64)
        cells = np.concatenate([index.nb[index.cam_pos[index.cam_indptr[k]:index.cam_indptr[k + 1]]] for k in cams])
    flat = np.bincount(cells, minlength=index.n_nodes * index.n_bins)
    return flat.reshape(index.n_nodes, index.n_bins)


def energy_of_subset(index: PairIndex, subset, cfg: EnergyConfig, per_node: bool = False) -> EnergyTerms:
    """Energy of the cameras ``subset`` (indices into the index's cameras), from scratch."""
    subset = np.unique(np.asarray(subset, np.int64))
    return energy_from_hist(histogram(index, subset), len(subset), cfg, per_node)


def compute_energy(cams: Cameras, nodes: np.ndarray, cfg: EnergyConfig = EnergyConfig(),
                   visibility: Visibility | None = None, per_node: bool = False) -> EnergyTerms:
    """E(cams) over nodes [M, 3], from scratch."""
    index = build_pair_index(cams, nodes, cfg.bins, visibility)
    return energy_from_hist(histogram(index), len(cams), cfg, per_node)


def energy_reference(cams: Cameras, nodes: np.ndarray, cfg: EnergyConfig = EnergyConfig()) -> EnergyTerms:
    """Plain-Python E(cams), written straight from the definitions (slow; for tests).

    Only the frustum test is shared with the fast path (its exact operation order defines
    where a boundary falls); binning, histograms, TV and powers are written out here.
    """
    nt, nph = cfg.n_theta, cfg.n_phi
    if cfg.binning == "paper":
        u = [(math.cos(i * math.pi / nt) - math.cos((i + 1) * math.pi / nt)) / 2 / nph
             for i in range(nt) for _ in range(nph)]
    else:
        u = [1.0 / (nt * nph)] * (nt * nph)
    N = len(cams)
    centres = cams.centres.tolist()
    ang_total = freq_total = 0.0
    for p in np.asarray(nodes, np.float64).tolist():
        vis = frustum_visible_reference(cams, p) if N else []
        hist = [0] * (nt * nph)
        n = 0
        for k in range(N):
            if not vis[k]:
                continue
            d = [centres[k][j] - p[j] for j in range(3)]
            r = math.sqrt(d[0] ** 2 + d[1] ** 2 + d[2] ** 2)
            c = max(-1.0, min(1.0, d[2] / r))
            if cfg.binning == "paper":
                it = min(int(math.floor(math.acos(c) / (math.pi / nt))), nt - 1)
            else:
                it = min(int(math.floor((1.0 - c) / 2.0 * nt)), nt - 1)
            ip = int(math.floor((math.atan2(d[1], d[0]) + math.pi) / (2 * math.pi / nph))) % nph
            hist[it * nph + ip] += 1
            n += 1
        tv = 1.0 if n == 0 else 0.5 * sum(abs(hist[b] / n - u[b]) for b in range(nt * nph))
        ang_total += 1.0 - tv
        freq_total += (n / N) ** cfg.gamma if n > 0 else 0.0
    return EnergyTerms(ang_total + freq_total, ang_total, freq_total, N, len(nodes))
