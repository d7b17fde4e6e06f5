"""Frames evenly spaced along the capture path by view change (arc length in the view distance).

Every n-th frame (``stride``) spaces frames evenly in *time*, so a walker who lingers gets many
near-identical frames; view medoids space them evenly in the view distance but merge passes
that revisit a place (a second lap counts as a duplicate of the first). This spaces them evenly
in the *cumulative* view distance along the path in capture order (the steps of
:func:`curate.select.medoids.path_weights`, each capped at ``PATH_CAP`` median steps so a cut
between two sequences counts as a short step): a stretch where the walker lingered gets few
frames, and every pass over a place gets its own.

Memory [K] (the path-order test: [512, K]); time O(K log K).
"""

from __future__ import annotations

import numpy as np

from curate.core.cameras import Cameras
from curate.select.medoids import PATH_CAP, PATH_ORDER_MIN, embed, path_order_share, view_depths


def arc_length(c: np.ndarray, a: np.ndarray, power: float = 1.0) -> np.ndarray | None:
    """[K] cumulative view distance along the embedded views ``c``, ``a`` [K, 3] in capture order
    (0 at the first), each step capped at ``PATH_CAP`` median steps and raised to ``power`` (in
    median steps: 1 is the arc length, 0 counts frames as every n-th frame does); None when the
    views do not form a path: fewer than 3, every step 0, or :func:`path_order_share` below
    ``PATH_ORDER_MIN``."""
    K = len(c)
    if K < 3:
        return None
    step = np.linalg.norm(c[1:] - c[:-1], axis=1) + np.linalg.norm(a[1:] - a[:-1], axis=1)   # [K-1]
    med = float(np.median(step))
    if not (np.isfinite(med) and med > 0) or path_order_share(c, a) < PATH_ORDER_MIN:
        return None
    return np.concatenate([[0.0], np.cumsum(np.minimum(step / med, PATH_CAP) ** power)])


def targets(s: np.ndarray, budget: int, fixed=()) -> np.ndarray:
    """[budget] arc positions for new frames on the path ``s`` [K] (non-decreasing), with the
    frames ``fixed`` (indices) already chosen: the fixed frames cut the path into pieces, and each
    new frame goes to the piece whose spacing is then largest (a piece between two chosen frames
    with m new ones has spacing length / (m + 1); a piece at an open end, length / (m + 1/2); the
    whole path with none fixed, length / m), placed evenly within it. Sorted."""
    b = max(0, int(budget))
    if b == 0:
        return np.zeros(0)
    cuts = np.unique(s[np.asarray(list(fixed), np.int64)]) if len(fixed) else np.zeros(0)
    edges = np.concatenate([[s[0]], cuts, [s[-1]]])
    length = np.diff(edges)                                          # [pieces]
    open_lo = np.zeros(len(length), bool)
    open_hi = np.zeros(len(length), bool)
    open_lo[0] = len(cuts) == 0 or cuts[0] > s[0]
    open_hi[-1] = len(cuts) == 0 or cuts[-1] < s[-1]
    ends = open_lo.astype(float) * 0.5 + open_hi.astype(float) * 0.5      # 1/2 per open end
    m = np.zeros(len(length), np.int64)
    with np.errstate(divide="ignore"):                               # the whole path, none placed: inf
        for _ in range(b):                                           # largest spacing first (ties: first piece)
            m[np.argmax(length / (m + 1 - ends))] += 1
    out = []
    for k in np.flatnonzero(m):
        step = length[k] / (m[k] + 1 - ends[k])
        first = edges[k] + (0.5 if open_lo[k] else 1.0) * step
        out.append(first + step * np.arange(m[k]))
    return np.sort(np.concatenate(out))


def snap(s: np.ndarray, t: np.ndarray, avail: np.ndarray) -> list[int]:
    """Distinct indices of ``avail`` (sorted pool indices) whose positions ``s[avail]`` are
    nearest the sorted targets ``t``, increasing with ``t`` (one each while there are enough)."""
    b = min(len(t), len(avail))
    if b == 0:
        return []
    sa = s[avail]
    hi = np.clip(np.searchsorted(sa, t[:b]), 1, len(sa) - 1) if len(sa) > 1 else np.zeros(b, np.int64)
    lo = np.maximum(hi - 1, 0)
    idx = np.where(np.abs(sa[lo] - t[:b]) <= np.abs(sa[hi] - t[:b]), lo, hi)
    for j in range(1, b):                                            # distinct and increasing,
        idx[j] = max(idx[j], idx[j - 1] + 1)                         # room left for the rest
    idx[b - 1] = min(idx[b - 1], len(sa) - 1)
    for j in range(b - 2, -1, -1):
        idx[j] = min(idx[j], idx[j + 1] - 1)
    return [int(avail[i]) for i in idx]


def path_stride(cams: Cameras, budget: int, nodes=None, index=None, initial=(),
                look_scale: float = 1.0, power: float = 1.0) -> list[int] | None:
    """``budget`` more pool indices evenly spaced along the path's view distance around the
    ``initial`` ones, or None when the cameras are not in capture order (:func:`arc_length`).
    ``look_scale`` scales each camera's look-at depth: below 1 a turn of the head counts for
    less against a step of the walker; ``power`` (:func:`arc_length`) between 0 and 1 moves it
    towards every n-th frame."""
    c, a = embed(cams, look_scale * view_depths(cams, nodes, index))
    s = arc_length(c, a, power)
    if s is None:
        return None
    initial = [int(k) for k in dict.fromkeys(initial)]
    avail = np.setdiff1d(np.arange(len(cams)), np.asarray(initial, np.int64))
    b = min(max(0, int(budget)), len(avail))
    return snap(s, targets(s, b, initial), avail)
