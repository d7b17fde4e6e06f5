"""Frames a model placed off their video's path: a run of consecutive frames that jumps away from the
walk and back, found by the frames' agreement with their neighbours in capture order.

A video is a continuous path: between two frames a tenth of a second apart the camera moves a hand's
breadth. An incremental model can still register a stretch of a take in the wrong place, a piece hinged on
a few wrong matches whose frames agree with each other and with the points they see: only the path finds
it (the case that showed it, office.mp4 in two takes: docs/investigations/sfm.md).

:func:`off_path` works on one take's registered frames in time order and flags an *island*: a run
of frames entered by a jump and left by the next jump (a step at a speed over :data:`JUMP_FACTOR`
times the take's median speed), no jump inside it, while the frames just before and just after it
are within that speed of each other, the way a real walk would have gone; a run of at most half the
take. A take that speeds up after a pause has an entry without a way back (and, walking, a jump at
every step: no run between two of them holds still); a cut in a video (frames dropped between
candidates) is a gap in time the speed allows for. Neither is an island.

:func:`path_jumps` finds what is left once islands are out: a jump with no way back, at over
:data:`FOLD_FACTOR` times the speed of the steps around it. A model folded at such a step holds every
frame, and the frames on each side agree with their neighbours; which side is wrong the path cannot
say, so nothing is left out: the user is told (``curate.sfm.warn.path_warning``).

:func:`drop_off_path` and :func:`jumps_along` apply both to the takes of a mapper's models.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

JUMP_FACTOR = 10.0
"""A step between consecutive frames of a take is a jump when its speed (distance over time between
them) exceeds this many times the take's median speed. office.mp4's wrong stretch: entered and left at
21-32 times the median; the largest step of a sound video measured: 4.59 times (a rendered second
session; office.mp4: 3.75; the fox photos played as a video: one jump of 13.4 times with no way back).
10 sits midway (geometrically) between 4.59 and 21 (research.path_check, docs/sfm.md)."""


FOLD_FACTOR = 20.0
"""A jump with no way back is reported when its speed exceeds this many times the speed around it
(:func:`step_ratios`: the steps on each side, at least the take's median speed). The one fold measured
(office.mp4 in two takes, one local refinement per photo, since withdrawn: every frame 35 deg off,
median) jumped at 44.75 times the median; the largest one-way steps of sound models:
13.4 times (the fox photos played as a video: the photographer's uneven steps), at most 4.59 for videos
(research.path_check, docs/sfm.md; against the take's median, which bounds the ratio to the speed
around a step from above). 20 sits above every sound capture measured, under the fold by 2.2x."""


JUMP_WINDOW = 10
"""Steps on each side of a step that :func:`path_jumps` compares it with (a second at 10 candidates a second)."""


def speeds(t: np.ndarray, c: np.ndarray) -> np.ndarray:
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
    v = speeds(t, c)
    med = float(np.median(v))
    if not med > 0:
        return np.zeros(0, int)
    limit = factor * med
    jumps = np.flatnonzero(v > limit) + 1       # frame i is reached by a jump from frame i-1
    out: set[int] = set()
    for a, b in zip(jumps[:-1], jumps[1:]):     # an island [a, b): entered at a, left at b, no jump inside
        if b - a > n // 2 or a - 1 in out:     # the frame before it must be on the path
            continue
        way = speeds(t[[a - 1, b]], c[[a - 1, b]])[0]
        if way <= limit:
            out.update(range(a, b))
    return np.array(sorted(out), int)


def step_ratios(t: np.ndarray, c: np.ndarray, window: int = JUMP_WINDOW) -> np.ndarray:
    """[n-1] each step's speed over the speed around it: the median of the ``window`` steps on each side,
    itself at least the take's median (all zeros when the take never moves). Measured against its
    neighbours, not the take as a whole, so that walking on after a long pause (every step fast against a
    take that mostly stood still) stays near 1.

    t: [n] seconds, increasing; c: [n, 3] camera centres (finite; see :func:`path_jumps`)."""
    v = speeds(t, c)
    if len(v) == 0:
        return v
    med = float(np.median(v))
    if not med > 0:
        return np.zeros_like(v)
    ref = np.array([max(float(np.median(np.r_[v[max(i - window, 0):i], v[i + 1:i + 1 + window]]))
                        if len(v) > 1 else med, med) for i in range(len(v))])
    with np.errstate(over="ignore", invalid="ignore"):
        return v / ref


def path_jumps(t: np.ndarray, c: np.ndarray, factor: float = FOLD_FACTOR, window: int = JUMP_WINDOW
               ) -> list[tuple[int, float]]:
    """The lone jumps of a take: [(i, ratio)], frame i reached from frame i-1 at ``ratio`` > ``factor`` times
    the speed around it (:func:`step_ratios`). Run :func:`off_path` first and leave its frames out: an
    island's way in and out are such jumps.

    t: [n] seconds, increasing (one take's registered frames in time order).
    c: [n, 3] their camera centres in the model.
    Returns [] under 4 frames, for a take that never moves, and for non-finite input.
    """
    t, c = np.asarray(t, np.float64), np.asarray(c, np.float64).reshape(-1, 3)
    if len(t) < 4 or not (np.isfinite(t).all() and np.isfinite(c).all()):
        return []
    r = step_ratios(t, c, window)
    return [(int(i) + 1, float(r[i])) for i in np.flatnonzero(r > factor)]


def video_takes(rec, when: dict) -> dict[str, list]:
    """{take: [(time, Image)] in time order} of the registered frames of ``rec`` that ``when``
    ({name: (take, time)}, :func:`frame_times`) places in time: video frames, numbered photos."""
    takes: dict[str, list] = {}
    for im in rec.images.values():
        if im.has_pose and im.name in when:
            takes.setdefault(when[im.name][0], []).append((when[im.name][1], im))
    for frames in takes.values():
        frames.sort(key=lambda x: x[0])
    return dict(sorted(takes.items()))


def frame_times(kept: list, numbered: bool = False) -> dict:
    """{working name: (take, seconds)} of the video frames among the PhotoRecords ``kept``; with
    ``numbered``, also the photos of each photo take (:func:`curate.sfm.prep.take_name`) whose names
    are numbered frames (:func:`curate.sfm.prep.looks_sequential`, which also makes them matched in
    sequence), their number standing for the time (a photo dropped or deleted between two is a
    longer time, not a faster step)."""
    from curate.sfm.prep import _trailing_number, looks_sequential, take_name
    out = {r.working: (r.extra["video_rel"], float(r.extra["time"])) for r in kept
           if r.extra.get("video_rel") is not None and r.extra.get("time") is not None}
    if numbered:
        takes: dict[str, list] = {}
        for r in kept:
            if r.working not in out and not r.extra.get("video"):
                takes.setdefault(take_name(r), []).append(r)
        for take, recs in takes.items():
            recs.sort(key=lambda r: r.rel)
            if looks_sequential([Path(r.rel).name for r in recs]):
                out.update((r.working, (take, float(_trailing_number(Path(r.rel).name)[1]))) for r in recs)
    return out


def times_and_centres(frames: list) -> tuple[np.ndarray, np.ndarray]:
    """([n] times, [n, 3] camera centres) of one take's frames (:func:`video_takes`), as the checks above take them."""
    return (np.array([x[0] for x in frames]), np.array([np.asarray(im.projection_center()) for _, im in frames]))


def drop_off_path(models: dict, kept: list) -> dict[str, list[str]]:
    """Deregister, in every model ({id: Reconstruction}), the video frames :func:`off_path`
    finds on an island off their take's path; ``kept``: the PhotoRecords (a frame's ``extra`` holds its
    ``video_rel`` and ``time``). Returns {take: [names]} of the frames left out."""
    when = frame_times(kept)
    out: dict[str, list[str]] = {}
    for rec in models.values():
        for tk, frames in video_takes(rec, when).items():
            for i in off_path(*times_and_centres(frames)):
                rec.deregister_frame(frames[i][1].frame_id)
                out.setdefault(tk, []).append(frames[i][1].name)
    return out


def jumps_along(rec, kept: list) -> dict[str, list[dict]]:
    """{take: [{"from", "to", "x_around"}]}: the one-way jumps (:func:`path_jumps`)
    of every video take in the model ``rec``, and of every take of numbered photos (in name order:
    frames a user extracted from a video), each between two consecutive registered frames, at
    ``x_around`` times the speed around the step (``step_ratios``). Run after :func:`drop_off_path`
    (which leaves numbered photos alone: only a warning rests on their order)."""
    out: dict[str, list[dict]] = {}
    for tk, frames in video_takes(rec, frame_times(kept, numbered=True)).items():
        for i, r in path_jumps(*times_and_centres(frames)):
            out.setdefault(tk, []).append({"from": frames[i - 1][1].name, "to": frames[i][1].name,
                                           "x_around": round(r, 1) if np.isfinite(r) else None})
    return out
