"""Exact, incremental greedy maximisation of the energy.

Each step adds the candidate c that maximises E(C + {c}). Nothing is recomputed from
scratch: with n_p views at node p, h_p its direction histogram, N = |C| and
``S = sum_p n_p ** gamma``, ``A = sum_p (1 - TV_p)``::

    E(C + {c}) = A + sum_{p in vis(c)} a_p(bin(c, p))
               + (N + 1) ** -gamma * (S + sum_{p in vis(c)} [(n_p + 1) ** gamma - n_p ** gamma])

The angular gain of one more view of node p in bin b is ``a_p(b) = TV_p - TV_p'(b)``
with ``TV_p'(b) = (G_p - |h_pb - (n_p+1) u_b| + |h_pb + 1 - (n_p+1) u_b|) / (2 (n_p+1))``
and ``G_p = sum_b |h_pb - (n_p+1) u_b|``: O(B) per node for the whole row. The growth
of N rescales every node's O_f by the same factor, which the global
``(N + 1) ** -gamma`` carries exactly.

Per candidate the two sums ``SA[c]`` (angular gains) and ``SF[c]`` (frequency gains)
are kept. Adding camera c* changes ``h`` and ``n`` only at the nodes c* observes, so
only their gain rows change, and only the (node, candidate) pairs at those nodes
update ``SA`` and ``SF``: a step costs O(B |vis(c*)| + pairs at vis(c*)).

Ties (scores within 1e-11 relative of the best) go to the lowest candidate index, in
the fast path and in the brute-force reference alike.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from curate.select.config import EnergyConfig
from curate.select.energy import energy_of_subset, pow_gamma
from curate.select.visibility import PairIndex, chunked_bincount

log = logging.getLogger(__name__)

TIE_RTOL = 1e-11
PAIR_CHUNK = 1 << 22  # pairs updated at once in a step (bounds scratch memory)


def argmax_lowest(scores: np.ndarray, available: np.ndarray) -> int:
    """Index of the best available score; near-ties (TIE_RTOL) go to the lowest index. -1 if none."""
    if not np.any(available):
        return -1
    s = np.where(available, scores, -np.inf)
    best = s.max()
    tol = TIE_RTOL * max(1.0, abs(best))
    return int(np.flatnonzero(s >= best - tol)[0])


@dataclass
class GreedyTrace:
    """What the greedy selection did.

    Attributes:
        chosen: candidate indices in the order added (the initial ones excluded).
        initial: candidates taken as already chosen.
        energy, angular, frequency: [len(chosen)] E and its parts after each step.
        step_seconds: [len(chosen)] wall time of each step.
        setup_seconds: time to initialise the incremental state.
    """

    chosen: list[int] = field(default_factory=list)
    initial: list[int] = field(default_factory=list)
    energy: list[float] = field(default_factory=list)
    angular: list[float] = field(default_factory=list)
    frequency: list[float] = field(default_factory=list)
    step_seconds: list[float] = field(default_factory=list)
    setup_seconds: float = 0.0


class NodeState:
    """Per-node state of the energy for a camera set that grows one camera at a time.

    Attributes:
        hist: [M, B] views per node and direction bin; n: [M] views per node; N: cameras.
        tv: [M] TV per node; A = sum_p (1 - TV_p); S = sum_p n_p ** gamma.
        gain: [M, B] angular gain of one more view of node p in bin b, ``TV_p - TV_p'(b)``.
        fgain: [M] ``(n_p + 1) ** gamma - n_p ** gamma``.
    """

    def __init__(self, n_nodes: int, cfg: EnergyConfig, backend: str = "auto"):
        """``backend``: "numba" (compiled step), "numpy" (the reference), or "auto" (numba when importable)."""
        if backend not in ("auto", "numba", "numpy"):
            raise ValueError(f"backend must be auto, numba or numpy, got {backend!r}")
        from curate.select.greedy_kernel import kernel
        self.kernel = kernel() if backend != "numpy" else None
        if backend == "numba" and self.kernel is None:
            raise RuntimeError("backend 'numba' asked for, but numba is not importable")
        self.cfg = cfg
        self.shares = cfg.bins.shares()
        M, B = n_nodes, cfg.bins.n_bins
        self.hist = np.zeros((M, B), np.int32)
        self.n = np.zeros(M, np.int64)
        self.N = 0
        self.tv = np.ones(M)
        self.A = 0.0
        self.S = 0.0
        self.gain = np.broadcast_to(self.shares, (M, B)).copy()
        self.fgain = np.ones(M)

    def energy(self) -> tuple[float, float, float]:
        """(E, angular, frequency) of the current set."""
        freq = self.S / float(self.N) ** self.cfg.gamma if self.N > 0 else 0.0
        return self.A + freq, self.A, freq

    def scores_of(self, index: PairIndex) -> np.ndarray:
        """[K] E(C + {c}) for each camera c of another index over the same nodes (one pass over its pairs)."""
        B = index.n_bins
        SA = chunked_bincount(index.cam, index.n_cams, lambda s, e: self.gain.ravel()[index.nb[s:e]])
        SF = chunked_bincount(index.cam, index.n_cams, lambda s, e: self.fgain[index.nb[s:e] // B])
        return self.A + SA + (self.S + SF) / float(self.N + 1) ** self.cfg.gamma

    def _rows(self, nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Gain rows [k, B] and frequency gains [k] for the current counts at ``nodes``."""
        n1 = (self.n[nodes] + 1).astype(np.float64)
        dev = self.hist[nodes] - n1[:, None] * self.shares[None, :]   # h - (n+1) u
        after = np.abs(dev + 1.0)
        np.abs(dev, out=dev)
        G = dev.sum(1, keepdims=True)
        after -= dev
        after += G
        after *= (0.5 / n1)[:, None]                                    # TV'(b) for each b
        np.clip(after, 0.0, 1.0, out=after)
        gain = np.subtract(self.tv[nodes, None], after, out=after)
        fg = pow_gamma(n1, self.cfg.gamma) - pow_gamma(n1 - 1, self.cfg.gamma)
        return gain, fg

    def add_best_of(self, index: PairIndex) -> int:
        """Add the candidate camera of ``index`` (a pair index over candidates, not over the state's cameras)
        that raises the energy most, the lowest index on ties; returns it. One step of the paper's
        progressive placement (Algorithm 1): ``curate simulate`` and ``curate suggest`` both take it."""
        k = argmax_lowest(self.scores_of(index), np.ones(index.n_cams, bool))
        self.add(*index.camera_pairs(k))
        return k

    def add_compiled(self, nodes: np.ndarray, bins: np.ndarray, index: PairIndex | None = None,
                     SA: np.ndarray | None = None, SF: np.ndarray | None = None) -> None:
        """:meth:`add` by the compiled kernel; with ``index``, also updates the candidate
        sums ``SA``, ``SF`` [K] of its cameras in the same pass."""
        self.N += 1
        if nodes.size == 0:
            return
        track = index is not None
        if not track:
            index_arrays = (np.zeros(1, np.int64), np.zeros(0, np.int32), np.zeros(0, np.int64))
            SA = SF = np.zeros(0)
        else:
            index_arrays = (index.indptr, index.cam, index.nb)
        dA, dS = self.kernel(np.ascontiguousarray(nodes, np.int64), np.ascontiguousarray(bins, np.int64),
                             self.hist, self.n, self.tv, self.gain, self.fgain, self.shares, float(self.cfg.gamma),
                             *index_arrays, SA, SF, track)
        self.A += dA
        self.S += dS

    def add(self, nodes: np.ndarray, bins: np.ndarray):
        """Add one camera observing ``nodes`` [k] (ascending, distinct) in direction ``bins`` [k].

        Returns:
            (dgain [k, B], dfgain [k]): how the gain rows of those nodes changed
            (numpy step; None with the compiled one).
        """
        if self.kernel is not None:
            self.add_compiled(nodes, bins)
            return None
        self.N += 1
        if nodes.size == 0:
            return np.zeros((0, self.hist.shape[1])), np.zeros(0)
        old_gain, old_f = self.gain[nodes], self.fgain[nodes]
        self.S += float(old_f.sum())
        # The new TV of each touched node is the TV'(b*) its gain row already holds.
        tv_new = self.tv[nodes] - old_gain[np.arange(nodes.size), bins]
        self.A -= float((tv_new - self.tv[nodes]).sum())
        self.tv[nodes] = tv_new
        self.hist[nodes, bins] += 1
        self.n[nodes] += 1
        new_gain, new_f = self._rows(nodes)
        self.gain[nodes], self.fgain[nodes] = new_gain, new_f
        new_gain -= old_gain
        return new_gain, new_f - old_f


class GreedyState:
    """:class:`NodeState` plus, for every candidate of a :class:`PairIndex`, the sums of the
    gains over the nodes it observes, kept up to date as cameras are added."""

    def __init__(self, index: PairIndex, cfg: EnergyConfig, track_candidates: bool = True, backend: str = "auto"):
        """``track_candidates=False`` keeps only E of the set (no per-candidate scores);
        ``backend`` as for :class:`NodeState`."""
        self.index, self.cfg, self.track = index, cfg, track_candidates
        self.nodes = NodeState(index.n_nodes, cfg, backend)
        self.taken = np.zeros(index.n_cams, bool)
        if self.track:  # initially every gain is its bin's share, every frequency gain 1
            K, B, shares = index.n_cams, index.n_bins, self.nodes.shares
            self.SA = chunked_bincount(index.cam, K, lambda s, e: shares[index.nb[s:e] % B])
            self.SF = chunked_bincount(index.cam, K).astype(np.float64)

    def energy(self) -> tuple[float, float, float]:
        """(E, angular, frequency) of the current set."""
        return self.nodes.energy()

    def scores(self) -> np.ndarray:
        """[K] E(C + {c}) for every candidate c (taken ones included, meaningless for them)."""
        st = self.nodes
        return st.A + self.SA + (st.S + self.SF) / float(st.N + 1) ** self.cfg.gamma

    def add(self, k: int) -> None:
        """Add candidate k to the set and update every candidate's score sums."""
        idx = self.index
        B = idx.n_bins
        nodes, bins = idx.camera_pairs(k)
        self.taken[k] = True
        if self.nodes.kernel is not None:
            self.nodes.add_compiled(nodes, bins, *((idx, self.SA, self.SF) if self.track else ()))
            return
        dgain, dF_node = self.nodes.add(nodes, bins)
        if not self.track or nodes.size == 0:
            return
        # Every (node, candidate) pair at the touched nodes: concatenated node ranges,
        # in chunks of about PAIR_CHUNK pairs so scratch memory stays bounded.
        starts, lens = idx.indptr[nodes], idx.indptr[nodes + 1] - idx.indptr[nodes]
        csum = np.cumsum(lens)
        cuts = np.searchsorted(csum, np.arange(PAIR_CHUNK, int(csum[-1]), PAIR_CHUNK), side="left")
        for a, b in zip(np.r_[0, cuts], np.r_[cuts, nodes.size]):
            if a == b:
                continue
            L = lens[a:b]
            cs = np.cumsum(L)
            offs = np.arange(int(cs[-1]), dtype=np.int64)
            offs += np.repeat(starts[a:b] - cs + L, L)
            pc = idx.cam[offs]
            # Pair cell node*B + b -> row of the touched-node tables: local*B + b.
            cell = np.repeat((np.arange(a, b) - nodes[a:b]) * B, L)
            cell += idx.nb[offs]
            self.SA += np.bincount(pc, weights=dgain.ravel()[cell], minlength=idx.n_cams)
            self.SF += np.bincount(pc, weights=np.repeat(dF_node[a:b], L), minlength=idx.n_cams)


def greedy_select(index: PairIndex, budget: int, cfg: EnergyConfig = EnergyConfig(), initial=(),
                  progress: bool = False, backend: str = "auto") -> GreedyTrace:
    """Greedily add ``budget`` candidates (fewer if the pool runs out) to ``initial``.

    Args:
        index: visibility pairs of the candidate cameras.
        budget: number of candidates to add.
        cfg: energy parameters.
        initial: candidate indices already taken (kept, not counted in the budget).
        backend: "auto" (compiled step when numba is importable), "numba" or "numpy".
    """
    t0 = time.perf_counter()
    st = GreedyState(index, cfg, backend=backend)
    trace = GreedyTrace(initial=[int(k) for k in initial])
    for k in trace.initial:
        if not st.taken[k]:
            st.add(k)
    trace.setup_seconds = time.perf_counter() - t0
    steps = range(min(int(budget), int((~st.taken).sum())))
    if progress:
        from tqdm import tqdm
        steps = tqdm(steps, desc="select", unit="cam", leave=False, delay=1.0)
    for _ in steps:
        ts = time.perf_counter()
        k = argmax_lowest(st.scores(), ~st.taken)
        st.add(k)
        e, a, f = st.energy()
        trace.chosen.append(k)
        trace.energy.append(e)
        trace.angular.append(a)
        trace.frequency.append(f)
        trace.step_seconds.append(time.perf_counter() - ts)
    return trace


def trace_energy(index: PairIndex, cfg: EnergyConfig, initial, order) -> tuple[list, list, list]:
    """E, angular and frequency after each camera of ``order`` is added to ``initial``."""
    st = GreedyState(index, cfg, track_candidates=False)
    for k in dict.fromkeys(initial):
        st.add(int(k))
    out: tuple[list, list, list] = ([], [], [])
    for k in order:
        st.add(int(k))
        for lst, v in zip(out, st.energy()):
            lst.append(v)
    return out


def bruteforce_scores(index: PairIndex, chosen, cfg: EnergyConfig, candidates=None) -> np.ndarray:
    """[K] E(chosen + {c}) recomputed from scratch for each candidate (reference; slow)."""
    chosen = list(chosen)
    cands = range(index.n_cams) if candidates is None else candidates
    out = np.full(index.n_cams, -np.inf)
    for c in cands:
        if c not in chosen:
            out[c] = energy_of_subset(index, chosen + [c], cfg).energy
    return out


def greedy_select_bruteforce(index: PairIndex, budget: int, cfg: EnergyConfig = EnergyConfig(),
                             initial=()) -> GreedyTrace:
    """The same greedy choice by recomputing E from scratch for every candidate at every step."""
    trace = GreedyTrace(initial=[int(k) for k in initial])
    chosen = list(dict.fromkeys(trace.initial))
    avail = np.ones(index.n_cams, bool)
    avail[chosen] = False
    for _ in range(min(int(budget), int(avail.sum()))):
        ts = time.perf_counter()
        k = argmax_lowest(bruteforce_scores(index, chosen, cfg), avail)
        chosen.append(k)
        avail[k] = False
        t = energy_of_subset(index, chosen, cfg)
        trace.chosen.append(k)
        trace.energy.append(t.energy)
        trace.angular.append(t.angular)
        trace.frequency.append(t.frequency)
        trace.step_seconds.append(time.perf_counter() - ts)
    return trace
