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

:func:`unexplained_steps` asks each step of a take in the model whether the two frames' own verified matches
agree with it: a model whose relative pose between consecutive frames fits under half of their matches was not
built from them (a blurred walk mapped into a wrong model keeps every frame near its neighbours, so the path
cannot see it; its steps' own matches can).
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


STEP_MAX_ERROR_PX = 4.0
"""A verified match of two consecutive frames fits the model's step between them when its Sampson distance under
the model's relative pose is at most this many pixels (COLMAP verifies matches at 4 px)."""


STEP_MIN_SHARE = 0.5
"""A step is unexplained when under this share of its frames' verified matches fit it (the majority rule of
research/model_check.py, set on the cut before these rows). Measured (research/step_fit.py,
docs/investigations/sfm.md#steps-their-matches-refute): the blurred walk's wrong models have 5 of 44 and 6 of 15
steps under it, the folded cut its fold at 0.00; of 12 other models kept, one has a step under it, at a frame 6.9
deg off the truth, and every step under 0.7 lies at a frame 4.3 deg or more off."""


STEP_MIN_INLIERS = 15
"""Steps whose frames share fewer verified matches are not checked (too few to say)."""


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


def drop_refuted(models: dict, kept: list, db: Path) -> dict[str, list[str]]:
    """Deregister, in every model ({id: Reconstruction}), the frames of a take in time order (video frames,
    numbered photos) that the steps their own matches refute blame (:func:`step_fits`, :func:`lone_refuted`): a
    frame every checked step of which is refuted, between neighbours whose other steps fit. ``kept``: the
    PhotoRecords; ``db``: the matches. Returns {take: [names]} of the frames left out."""
    out: dict[str, list[str]] = {}
    for rec in models.values():
        by_name = {im.name: im for im in rec.images.values() if im.has_pose}
        for tk, steps in step_fits(rec, kept, db).items():
            for name in lone_refuted(steps):
                rec.deregister_frame(by_name[name].frame_id)
                out.setdefault(tk, []).append(name)
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


def step_errors_px(xa: np.ndarray, xb: np.ndarray, cam_b_from_cam_a: np.ndarray, focal: float) -> np.ndarray:
    """[n] how far, in pixels, each match (``xa[i]`` in frame a, ``xb[i]`` in frame b; [n, 2] normalised image
    coordinates, ``Camera.cam_from_img``) is from agreeing with the relative pose ``cam_b_from_cam_a`` ([3, 4],
    OpenCV): its Sampson distance to the epipolar geometry, or, for a pose with no translation, its distance
    to the rotated point. ``focal`` (pixels) scales normalised units to pixels. Never NaN: a match the pose
    cannot place (behind the camera under a pure rotation, non-finite input) is infinitely far."""
    xa, xb = np.asarray(xa, np.float64).reshape(-1, 2), np.asarray(xb, np.float64).reshape(-1, 2)
    P = np.asarray(cam_b_from_cam_a, np.float64)
    R, t = P[:3, :3], P[:3, 3]
    pa, pb = np.c_[xa, np.ones(len(xa))], np.c_[xb, np.ones(len(xb))]
    if not np.isfinite(P).all():
        return np.full(len(xa), np.inf)
    norm = float(np.linalg.norm(t))
    with np.errstate(all="ignore"):
        if norm > 1e-12:
            tn = t / norm
            E = np.array([[0, -tn[2], tn[1]], [tn[2], 0, -tn[0]], [-tn[1], tn[0], 0]]) @ R
            ea, eb = pa @ E.T, pb @ E          # epipolar lines of a's points in b, and of b's in a
            num = np.sum(pb * ea, axis=1) ** 2
            den = ea[:, 0] ** 2 + ea[:, 1] ** 2 + eb[:, 0] ** 2 + eb[:, 1] ** 2
            d = np.sqrt(num / np.maximum(den, 1e-30))
        else:
            q = pa @ R.T
            d = np.linalg.norm(q[:, :2] / q[:, 2:3] - xb, axis=1)
            d[q[:, 2] <= 0] = np.inf
        d = d * float(focal)
    return np.where(np.isfinite(d), d, np.inf)


def step_fits(rec, kept: list, db: Path, max_error_px: float = STEP_MAX_ERROR_PX,
              min_inliers: int = STEP_MIN_INLIERS) -> dict[str, list[tuple[str, str, int, float]]]:
    """{take: [(from, to, inliers, fit)]} of every take of the model ``rec`` that has an order in time (video
    frames, numbered photos: :func:`frame_times`): each step between consecutive registered frames that share
    ``min_inliers`` verified matches or more in the database ``db``, in time order, with the share of those
    matches within ``max_error_px`` of the model's relative pose (:func:`step_errors_px`). Takes with no step
    checked are left out."""
    from curate.sfm.native import load as load_pycolmap
    pycolmap = load_pycolmap()
    takes = video_takes(rec, frame_times(kept, numbered=True))
    out: dict[str, list] = {}
    if not takes:
        return out
    with pycolmap.Database.open(Path(db)) as d:
        ids = {im.name: im.image_id for im in d.read_all_images()}
        keypoints: dict[int, np.ndarray] = {}

        def kp(i: int) -> np.ndarray:
            if i not in keypoints:
                keypoints[i] = np.asarray(d.read_keypoints(i), np.float64)[:, :2]
            return keypoints[i]

        for tk, frames in takes.items():
            steps = []
            for (_, a), (_, b) in zip(frames[:-1], frames[1:]):
                ia, ib = ids.get(a.name), ids.get(b.name)
                if ia is None or ib is None or not d.exists_two_view_geometry(ia, ib):
                    continue
                m = d.read_two_view_geometry(ia, ib).inlier_matches
                if len(m) < min_inliers:
                    continue
                ca, cb = rec.cameras[a.camera_id], rec.cameras[b.camera_id]
                xa, xb = ca.cam_from_img(kp(ia)[m[:, 0]]), cb.cam_from_img(kp(ib)[m[:, 1]])
                rel = (b.cam_from_world() * a.cam_from_world().inverse()).matrix()
                focal = float(ca.focal_length_x * ca.focal_length_y * cb.focal_length_x * cb.focal_length_y) ** 0.25
                fit = float(np.mean(step_errors_px(xa, xb, rel, focal) <= max_error_px))
                steps.append((a.name, b.name, int(len(m)), fit))
            if steps:
                out[tk] = steps
    return out


def unexplained_steps(rec, kept: list, db: Path, max_error_px: float = STEP_MAX_ERROR_PX,
                      min_share: float = STEP_MIN_SHARE, min_inliers: int = STEP_MIN_INLIERS) -> dict[str, dict]:
    """{take: {"checked": steps checked, "unexplained": [{"from", "to", "inliers", "fit"}]}} of every take of
    the model ``rec`` that has an order in time (:func:`step_fits`): a step is unexplained when under
    ``min_share`` of its frames' verified matches are within ``max_error_px`` of the model's relative pose
    (``fit``: that share, rounded)."""
    return {tk: {"checked": len(steps),
                 "unexplained": [{"from": a, "to": b, "inliers": n, "fit": round(f, 2)}
                                 for a, b, n, f in steps if f < min_share]}
            for tk, steps in step_fits(rec, kept, db, max_error_px, min_inliers).items()}


def lone_refuted(steps: list[tuple[str, str, int, float]], min_share: float = STEP_MIN_SHARE) -> list[str]:
    """The frames of one take that its checked steps (:func:`step_fits`, in time order) blame: every checked step
    of the frame is refuted (fit under ``min_share``), it has one at least, and the frame at the other end of each
    of them has a step that fits. A frame turned off its neighbours is refuted on both sides, each neighbour
    confirmed on its other side; a frame at the end of what was checked (the next frames not registered) has one
    step. A fold (one refuted step between two stretches that fit) and a stretch of refuted steps (a wrong
    model) blame no frame: the steps cannot say which side is wrong."""
    bad: dict[str, int] = {}
    good: set[str] = set()
    for a, b, _, fit in steps:
        for f in (a, b):
            if fit < min_share:
                bad[f] = bad.get(f, 0) + 1
            else:
                good.add(f)
    out = []
    for f in bad:
        if f in good:
            continue
        others = [b if a == f else a for a, b, _, fit in steps if f in (a, b)]
        if all(o in good for o in others):
            out.append(f)
    return out
