"""Frames a model placed off their video's path: a run of consecutive frames that jumps away from the
walk and back (issue 36, part 1: a frame checked by its agreement with its neighbours in capture order).

A video is a continuous path: between two frames a tenth of a second apart the camera moves a
hand's breadth. An incremental model can still register a stretch of a take in the wrong place, a
piece hinged on a few wrong matches: office.mp4 cut into two takes that cross the walk's weak stretch
(its frames 173-186), mapped with one local refinement per photo (since withdrawn), came back as one
model of 371 frames in which 14 of them, from both takes, sat 42-46 deg off, entered and left by steps
21-32 times the take's median step (docs/sfm.md). Each such frame agrees with its own neighbours in the
piece, so no check of a frame against the points it sees finds it; the path does.

:func:`off_path` works on one take's registered frames in time order and flags an *island*: a run
of frames entered by a jump and left by the next jump (a step at a speed over :data:`JUMP_FACTOR`
times the take's median speed), no jump inside it, while the frames just before and just after it
are within that speed of each other, the way a real walk would have gone; a run of at most half the
take. A take that speeds up after a pause has an entry without a way back (and, walking, a jump at
every step: no run between two of them holds still); a cut in a video (frames dropped between
candidates) is a gap in time the speed allows for. Neither is an island.
"""

from __future__ import annotations

import numpy as np

JUMP_FACTOR = 10.0
"""A step between consecutive frames of a take is a jump when its speed (distance over time between
them) exceeds this many times the take's median speed. office.mp4's wrong stretch: entered and left at
21-32 times the median; the largest step of a sound video measured: 4.59 times (a rendered second
session; office.mp4: 3.75; the fox photos played as a video: one jump of 13.4 times with no way back).
10 sits midway (geometrically) between 4.59 and 21 (research.path_check, docs/sfm.md)."""


def _speeds(t: np.ndarray, c: np.ndarray) -> np.ndarray:
    """[n-1] distance over time between consecutive frames (time steps floored at a millisecond; a step
    too large for a float is infinitely fast)."""
    with np.errstate(over="ignore", invalid="ignore"):
        d = np.linalg.norm(np.diff(c, axis=0), axis=1)
    return np.where(np.isfinite(d), d, np.inf) / np.maximum(np.diff(t), 1e-3)


def off_path(t: np.ndarray, c: np.ndarray, factor: float = JUMP_FACTOR) -> np.ndarray:
    """Indices of the frames that form islands off a take's path.

    t: [n] seconds, increasing (one take's registered frames in time order).
    c: [n, 3] their camera centres in the model.
    Returns [k] int indices into t, sorted (empty under 4 frames or when the take never moves).
    """
    t, c = np.asarray(t, np.float64), np.asarray(c, np.float64).reshape(-1, 3)
    n = len(t)
    if n < 4 or not (np.isfinite(t).all() and np.isfinite(c).all()):
        return np.zeros(0, int)
    v = _speeds(t, c)
    med = float(np.median(v))
    if not med > 0:
        return np.zeros(0, int)
    limit = factor * med
    jumps = np.flatnonzero(v > limit) + 1       # frame i is reached by a jump from frame i-1
    out: set[int] = set()
    for a, b in zip(jumps[:-1], jumps[1:]):     # an island [a, b): entered at a, left at b, no jump inside
        if b - a > n // 2 or a - 1 in out:     # the frame before it must be on the path
            continue
        way = _speeds(t[[a - 1, b]], c[[a - 1, b]])[0]
        if way <= limit:
            out.update(range(a, b))
    return np.array(sorted(out), int)
