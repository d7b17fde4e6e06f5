"""Compiled (numba) greedy step: the same arithmetic as the numpy step in
:mod:`curate.select.greedy`, fused into one pass over the touched nodes and their pairs.

The numpy step stays as the reference (tests run both against brute force) and as the
fallback where numba is missing. Summation order differs slightly (the compiled step
adds each pair's change straight into the candidate sums), so the two agree to
rounding, well inside the tie tolerance.
"""

from __future__ import annotations

import functools
import logging

import numpy as np

log = logging.getLogger(__name__)


@functools.lru_cache(maxsize=1)
def kernel():
    """The compiled step, or None when numba is not importable."""
    try:
        import numba
    except ImportError:  # pragma: no cover - numba is a dependency
        log.info("numba not available: greedy steps use numpy")
        return None

    @numba.njit(cache=True, nogil=True)
    def add_step(nodes, bins, hist, n, tv, gain, fgain, shares, gamma,
                 indptr, cam, nb, SA, SF, track):  # pragma: no cover - compiled
        """Add one camera observing ``nodes`` [k] in ``bins`` [k]; returns (dA, dS)."""
        B = shares.size
        old = np.empty(B)
        dA = 0.0
        dS = 0.0
        for i in range(nodes.size):
            p = nodes[i]
            b = bins[i]
            for j in range(B):
                old[j] = gain[p, j]
            oldf = fgain[p]
            dS += oldf
            tvn = tv[p] - old[b]
            dA += tv[p] - tvn
            tv[p] = tvn
            hist[p, b] += 1
            n[p] += 1
            n1 = n[p] + 1.0
            G = 0.0
            for j in range(B):
                G += abs(hist[p, j] - n1 * shares[j])
            for j in range(B):
                d = hist[p, j] - n1 * shares[j]
                t = ((abs(d + 1.0) - abs(d)) + G) * (0.5 / n1)  # the numpy step's order
                if t < 0.0:
                    t = 0.0
                elif t > 1.0:
                    t = 1.0
                gain[p, j] = tvn - t
            newf = n1 ** gamma - (n1 - 1.0) ** gamma
            fgain[p] = newf
            if track:
                df = newf - oldf
                base = p * B
                for q in range(indptr[p], indptr[p + 1]):
                    c = cam[q]
                    bb = nb[q] - base
                    SA[c] += gain[p, bb] - old[bb]
                    SF[c] += df
        return dA, dS

    return add_step
