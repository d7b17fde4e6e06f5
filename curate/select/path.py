"""Frames evenly spaced along the capture path by view change: method "path".

Every n-th frame (method "stride") spaces frames evenly in *time*: a walker who lingers gets
many near-identical frames, one who hurries gets few. View medoids space them evenly in the
view distance of :mod:`curate.select.medoids`, but merge passes that revisit a place (a second
lap counts as a duplicate of the first). This spaces them evenly in the *cumulative* view
distance along the path in capture order (name order: numbered video frames), each step
capped at ``PATH_CAP`` median steps so a cut between two sequences counts as a short step:
a stretch where the walker lingered gets few frames, and every pass over a place its own.

The look-at depths are scaled by ``PathConfig.look_scale`` (0.5): a turn of the head then counts
for half as much against a step of the walker as in view medoids' distance. On rendered walks,
frame pairs that differ by a step overlap less, and carry more parallax, than pairs that differ
by a turn of the same view distance; the scale was chosen on 21 walks against 1 and against
view medoids, and confirmed on 7 more and on the office (docs/investigations/selection.md#walk-rule).

With frames already chosen (``initial``), they cut the path into pieces, and the new frames
go where the largest spacing is then smallest (:func:`targets`). When the views are not in
capture order (:func:`curate.select.medoids.path_steps` returns None) there is no path:
:func:`path_select` returns None and the caller falls back (view medoids, with a note).

Memory [K] (the path-order test: [512, K]); time O(K log K).
"""

from __future__ import annotations


import numpy as np

from curate.core.cameras import Cameras
from curate.select.medoids import embed, path_steps, view_depths
from curate.select.config import PathConfig  # noqa: F401  (their home: the config)


def arc_length(c: np.ndarray, a: np.ndarray) -> np.ndarray | None:
    """[K] cumulative view distance along the embedded views ``c``, ``a`` [K, 3] in capture
    order, in median steps (0 at the first view; each step capped at ``PATH_CAP``), or None
    when the views do not form a path (:func:`curate.select.medoids.path_steps`)."""
    step = path_steps(c, a)                                          # [K-1] or None
    return None if step is None else np.concatenate([[0.0], np.cumsum(step)])


def targets(s: np.ndarray, budget: int, fixed=()) -> np.ndarray:
    """[budget] sorted arc positions for new frames on the path ``s`` [K] (non-decreasing).

    The frames ``fixed`` (indices into ``s``) cut the path into pieces; a piece between two
    fixed frames with m new ones has spacing length / (m + 1), one at an open end
    length / (m + 1/2) (its last frame serves one side), the whole path with none fixed
    length / m. Each new frame goes in turn to the piece whose spacing is then largest (ties:
    the first piece), which minimises the largest spacing; within a piece they are evenly
    spaced."""
    b = max(0, int(budget))
    if b == 0:
        return np.zeros(0)
    fixed = np.asarray(list(fixed), np.int64)
    cuts = np.unique(s[fixed]) if len(fixed) else np.zeros(0)
    edges = np.concatenate([[s[0]], cuts, [s[-1]]])                  # [pieces + 1]
    length = np.diff(edges)                                          # [pieces]
    open_lo = np.zeros(len(length), bool)
    open_hi = np.zeros(len(length), bool)
    open_lo[0] = len(cuts) == 0 or cuts[0] > s[0]
    open_hi[-1] = len(cuts) == 0 or cuts[-1] < s[-1]
    ends = 0.5 * open_lo + 0.5 * open_hi                             # [pieces] half a gap per open end
    m = np.zeros(len(length), np.int64)
    with np.errstate(divide="ignore"):                               # the whole path, none placed yet: inf
        for _ in range(b):
            m[np.argmax(length / (m + 1 - ends))] += 1
    out = []
    for k in np.flatnonzero(m):
        step = length[k] / (m[k] + 1 - ends[k])
        out.append(edges[k] + (0.5 if open_lo[k] else 1.0) * step + step * np.arange(m[k]))
    return np.sort(np.concatenate(out))


def snap(s: np.ndarray, t: np.ndarray, avail: np.ndarray) -> list[int]:
    """min(len(t), len(avail)) distinct entries of ``avail`` (sorted pool indices) whose
    positions ``s[avail]`` lie nearest the sorted targets ``t``, increasing with ``t``."""
    b = min(len(t), len(avail))
    if b == 0:
        return []
    sa = s[avail]                                                    # [n] non-decreasing
    if len(sa) > 1:
        hi = np.clip(np.searchsorted(sa, t[:b]), 1, len(sa) - 1)
    else:
        hi = np.zeros(b, np.int64)
    lo = np.maximum(hi - 1, 0)
    idx = np.where(np.abs(sa[lo] - t[:b]) <= np.abs(sa[hi] - t[:b]), lo, hi)
    for j in range(1, b):                                            # distinct and increasing ...
        idx[j] = max(idx[j], idx[j - 1] + 1)
    idx[b - 1] = min(idx[b - 1], len(sa) - 1)
    for j in range(b - 2, -1, -1):                                   # ... with room left for the rest
        idx[j] = min(idx[j], idx[j + 1] - 1)
    return [int(avail[i]) for i in idx]


def spaced(s: np.ndarray, budget: int, initial=()) -> list[int]:
    """``budget`` more indices (fewer if the path runs out) of the path ``s`` [K] evenly spaced
    around the ``initial`` ones (:func:`targets`, :func:`snap`), in increasing order."""
    initial = [int(k) for k in dict.fromkeys(initial)]
    avail = np.setdiff1d(np.arange(len(s)), np.asarray(initial, np.int64))
    b = min(max(0, int(budget)), len(avail))
    return snap(s, targets(s, b, initial), avail)


def path_select(cams: Cameras, budget: int, cfg: PathConfig = PathConfig(), initial=(),
                nodes: np.ndarray | None = None, index=None) -> list[int] | None:
    """``budget`` more pool indices (fewer if the pool runs out) evenly spaced along the
    capture path's view distance around the ``initial`` ones, in capture order; None when
    the cameras are not in capture order. ``nodes`` [N, 3] and ``index`` (the pool's pair
    index over them) give each camera's look-at depth (:func:`view_depths`), scaled by
    ``cfg.look_scale``."""
    s = arc_length(*embed(cams, cfg.look_scale * view_depths(cams, nodes, index)))
    return None if s is None else spaced(s, budget, initial)
