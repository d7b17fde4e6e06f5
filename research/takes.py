"""Several takes of one place (issue 36, part 3): test captures cut from the office walk, and how a
run folder's SfM kept each take, against the office's ground truth.

``make`` writes, under ``OUT``, one folder per case and a ``<case>.truth.json`` beside it (outside
the folder, so curate does not see it) mapping each take's frames to office frames:

* ``two_takes/``: ``walkA.mp4`` = office.mp4 frames 0..139 and the even frames of 140..239;
  ``walkB.mp4`` = frames 372..240 and the odd frames of 239..141 (played backwards: a second
  pass, the other way). They overlap over frames 140..239, each with every other frame there (the
  same frame in both takes would be dropped as a near-duplicate, which no real second pass has).
* ``two_takes_apart/``: ``walkA.mp4`` = frames 0..199, ``walkB.mp4`` = frames 372..200 (backwards):
  the takes meet only where the walk turned from one to the other (frames 199 and 200, far apart in
  name order) and where it comes back to places it saw before.
* ``three_takes/``: the same two and ``fox.mp4``, the fox photos (another scene) as a 10 fps
  video cropped to 540x360: a take that cannot join.
* ``sessions/`` (``--cases sessions``, rendered, no office): a hand-held walk of kind ``two_sessions``
  through the synthetic living room (:func:`curate.simulate.walks.hand_held_walk`, 320x240, 10 fps,
  motion blur), cut at its middle into ``session1.mp4`` (a loop) and ``session2.mp4`` (a second,
  lower loop the other way round, started elsewhere): a second pass that sees the room from
  elsewhere, not the same frames. Ground truth: ``sessions.cameras.json``.
* ``sessions_office/``, ``sessions_kitchen/``: the same walk through the other rendered rooms;
  ``sessions_foreign/``: the living room's two sessions and ``other_room.mp4``, 60 frames of the kitchen: a
  take that cannot join.
* ``video_photos/``: ``walk.mp4`` = office.mp4 frames 0..186, and every 5th office JPEG of
  frames 187..372 as photos. They share nothing but what the walk sees twice.

``eval`` reads ``RUN/sfm`` (``images.json``, ``cameras.json``, ``stage.json``) and prints one JSON
object: the models' sizes, per take its frames and how many are in the kept model, the matching
and mapping seconds, and the median / max rotation error of the kept frames with ground truth
after one similarity alignment of all of them (:func:`research.align.pose_errors`).

    python3 -m research.takes make --office ../shared/data/office --fox ../shared/data/fox --out /tmp/takes
    nice -n 10 python3 -m curate sfm /tmp/takes/two_takes --out /tmp/takes_runs/two
    python3 -m research.takes eval /tmp/takes_runs/two --truth /tmp/takes/two_takes.truth.json \
        --office ../shared/data/office
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import numpy as np

FPS = 10


def _decode(video: Path) -> list[np.ndarray]:
    """Every frame of ``video`` as [H, W, 3] uint8, in decoding order."""
    import av
    with av.open(str(video)) as c:
        return [f.to_ndarray(format="rgb24") for f in c.decode(c.streams.video[0])]


def write_video(frames: list[np.ndarray], path: Path, crf: int = 23) -> None:
    """``frames`` ([H, W, 3] uint8, one size) as an H.264 video at 10 fps."""
    import av
    path.parent.mkdir(parents=True, exist_ok=True)
    with av.open(str(path), mode="w", format="mp4") as c:
        s = c.add_stream("libx264", rate=FPS)
        s.width, s.height, s.pix_fmt = frames[0].shape[1], frames[0].shape[0], "yuv420p"
        s.options = {"crf": str(crf), "preset": "medium"}
        for rgb in frames:
            for pkt in s.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(rgb), format="rgb24")):
                c.mux(pkt)
        for pkt in s.encode():
            c.mux(pkt)


def _fox_frames(fox: Path, size=(540, 360)) -> list[np.ndarray]:
    """The fox photos (sorted), each centre-cropped to the aspect of ``size`` and resized to it."""
    from PIL import Image, ImageOps
    out = []
    for p in sorted((fox / "images").iterdir()):
        with Image.open(p) as im:
            out.append(np.asarray(ImageOps.fit(ImageOps.exif_transpose(im).convert("RGB"), size, Image.LANCZOS)))
    return out


CASES = ("two_takes", "two_takes_apart", "three_takes", "video_photos", "sessions", "sessions_office",
         "sessions_kitchen", "sessions_foreign")


def _render_chunk(args):
    """Rendered, motion-blurred uint8 frames of cameras ``idx`` of the sessions walk in ``room`` (worker)."""
    n, idx, room = args
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk, motion_blur
    scene = make_scene(room, 0)
    cams, omega = hand_held_walk(n, "two_sessions", seed=0, width=320, height=240, room=scene.interior, fps=FPS)
    rgb, _ = scene.render(cams[list(idx)])
    return [motion_blur(im, omega[i], float(cams.fx[i]), FPS / 120) for i, im in zip(idx, rgb)]


def _session_frames(room: str, n: int, jobs: int):
    """(cameras [n], frames [n]) of the two-session walk through the rendered ``room``."""
    from multiprocessing import Pool

    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk
    scene = make_scene(room, 0)
    cams, _ = hand_held_walk(n, "two_sessions", seed=0, width=320, height=240, room=scene.interior, fps=FPS)
    with Pool(jobs) as pool:
        chunks = [(n, list(range(a, min(a + 20, n))), room) for a in range(0, n, 20)]
        frames = [f for part in pool.map(_render_chunk, chunks) for f in part]
    return cams, frames


def make_sessions(out: Path, n: int = 300, jobs: int = 2, room: str = "livingroom", name: str = "sessions",
                  foreign: str | None = None) -> dict:
    """``out/<name>/session{1,2}.mp4`` and ``out/<name>.cameras.json`` (the rendered poses) of ``room``; with
    ``foreign``, a third take ``other_room.mp4``: the first session's first 60 frames in that other room, which
    shares nothing with the first (no truth: it must be left out)."""
    cams, frames = _session_frames(room, n, jobs)
    h = n // 2
    write_video(frames[:h], out / name / "session1.mp4")
    write_video(frames[h:], out / name / "session2.mp4")
    cams.save(out / f"{name}.cameras.json")
    videos = {"session1.mp4": list(range(h)), "session2.mp4": list(range(h, n))}
    if foreign is not None:
        write_video(_session_frames(foreign, n, jobs)[1][:60], out / name / "other_room.mp4")
        videos["other_room.mp4"] = None
    return {"videos": videos, "photos": {}, "cameras": str(out / f"{name}.cameras.json")}


def make(office: Path, fox: Path, out: Path, cases: tuple = CASES) -> dict:
    """Write ``cases`` under ``out``; returns {case: truth} (also in ``out/<case>.truth.json``)."""
    office_cases = {"two_takes", "two_takes_apart", "three_takes", "video_photos"} & set(cases)
    frames = _decode(office / "office.mp4") if office_cases else []
    n = len(frames)
    a = list(range(0, 140)) + list(range(140, 240, 2))
    b = list(range(n - 1, 239, -1)) + list(range(239, 140, -2))
    done: dict = {}
    if "two_takes" in cases or "three_takes" in cases:
        d = out / "two_takes"
        write_video([frames[i] for i in a], d / "walkA.mp4")
        write_video([frames[i] for i in b], d / "walkB.mp4")
        done["two_takes"] = {"videos": {"walkA.mp4": a, "walkB.mp4": b}, "photos": {}}
    if "two_takes_apart" in cases:
        d = out / "two_takes_apart"
        a2, b2 = list(range(0, 200)), list(range(n - 1, 199, -1))
        write_video([frames[i] for i in a2], d / "walkA.mp4")
        write_video([frames[i] for i in b2], d / "walkB.mp4")
        done["two_takes_apart"] = {"videos": {"walkA.mp4": a2, "walkB.mp4": b2}, "photos": {}}
    if "three_takes" in cases:
        d = out / "three_takes"
        d.mkdir(parents=True, exist_ok=True)
        for v in ("walkA.mp4", "walkB.mp4"):
            shutil.copyfile(out / "two_takes" / v, d / v)
        write_video(_fox_frames(fox), d / "fox.mp4")
        done["three_takes"] = {"videos": {"walkA.mp4": a, "walkB.mp4": b, "fox.mp4": None}, "photos": {}}
    if "video_photos" in cases:
        d = out / "video_photos"
        half = (n + 1) // 2
        write_video(frames[:half], d / "walk.mp4")
        imgs = sorted((office / "images").iterdir())
        photos = {}
        for i in range(half, n, 5):
            shutil.copyfile(imgs[i], d / imgs[i].name)
            photos[imgs[i].name] = i
        done["video_photos"] = {"videos": {"walk.mp4": list(range(half))}, "photos": photos}
    if "sessions" in cases:
        done["sessions"] = make_sessions(out)
    for room in ("office", "kitchen"):
        if f"sessions_{room}" in cases:
            done[f"sessions_{room}"] = make_sessions(out, room=room, name=f"sessions_{room}")
    if "sessions_foreign" in cases:
        done["sessions_foreign"] = make_sessions(out, name="sessions_foreign", foreign="kitchen")
    for k, v in done.items():
        (out / f"{k}.truth.json").write_text(json.dumps(v))
    return done


def evaluate(run: Path, truth_json: Path | None, office: Path | None) -> dict:
    """How ``RUN/sfm`` kept each take, and the rotation errors of the kept frames with ground truth."""
    from curate.sfm.io import load_sfm
    sfm = run / "sfm"
    st = json.loads((sfm / "stage.json").read_text())
    stats = st["stats"]
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    cams = load_sfm(run).cameras
    reg = set(cams.names)

    takes = take_counts(recs, reg)
    out = {"run": str(run), "matcher": stats.get("matcher"), "mapper": stats.get("mapper"),
           "model_sizes": stats.get("model_sizes"), "n_kept": stats.get("n_kept"),
           "takes": {k: f"{v[1]} of {v[0]}" for k, v in takes.items()},
           "cross_take": stats.get("cross_take"), "n_pairs_matched": stats.get("n_pairs_matched"),
           "n_pairs_verified": stats.get("n_pairs_verified"), "mappers_tried": stats.get("mappers_tried"),
           "timings": {k: st["timings"].get(k) for k in ("extract", "match", "map")},
           "seconds": st.get("seconds")}
    tj = json.loads(truth_json.read_text()) if truth_json is not None else {}
    if tj and (office is not None or tj.get("cameras")):
        e = errors_against_truth(cams, recs, tj, office)
        if e is not None:
            out.update({"n_with_truth": e["n_matched"], "rotation_deg_median": round(e["rotation_deg_median"], 2),
                        "rotation_deg_max": round(e["rotation_deg_max"], 2),
                        "over_5_deg": int(sum(r > 5 for r in e["rotation_deg"])),
                        "centre_rel_median": round(e["centre_rel_median"], 4)})
    return out


def take_counts(recs: list[dict], registered: set[str]) -> dict[str, list[int]]:
    """{take (its video, or "photos"): [frames kept, of them registered]} of the kept records ``recs`` of
    ``images.json``; ``registered``: the working names a model holds."""
    takes: dict = {}
    for r in recs:
        t = takes.setdefault((r.get("extra") or {}).get("video_rel") or "photos", [0, 0])
        t[0] += 1
        t[1] += r["working"] in registered
    return takes


def truth_of(recs: list[dict], tj: dict) -> dict[str, int]:
    """{working name: index of its true pose} of the kept records ``recs`` that have one in the case's truth
    ``tj`` (a ``<case>.truth.json``: each video's frames, and photos, to truth indices)."""
    gt_of = {}
    for r in recs:
        e = r.get("extra") or {}
        if e.get("video"):
            idx = tj["videos"].get(e["video_rel"])
            if idx is not None and idx[e["frame"]] is not None:
                gt_of[r["working"]] = idx[e["frame"]]
        elif r["rel"] in tj["photos"]:
            gt_of[r["working"]] = tj["photos"][r["rel"]]
    return gt_of


def global_model(run: Path, truth_json: Path, office: Path | None) -> dict:
    """COLMAP's global model of the run's matches as COLMAP returns it, before curate's checks: its size, each
    take's frames in it and the rotation errors of the frames with ground truth (the join the rule judged: a
    correct join has no frame over 5 deg and no frame of a take without truth)."""
    import tempfile

    from curate.sfm.model import cameras_from_reconstruction
    from research.sfm_mappers import map_with
    sfm = run / "sfm"
    recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
    tj = json.loads(truth_json.read_text())
    with tempfile.TemporaryDirectory() as tmp:
        models, seconds = map_with("global", sfm / "database.db", sfm / "images", Path(tmp))
        best = max(models.values(), key=lambda r: r.num_reg_images())
        cams = cameras_from_reconstruction(best, warn=False)[0]
    takes = take_counts(recs, set(cams.names))
    out = {"size": len(cams), "seconds": round(seconds, 1), "takes": {k: f"{v[1]} of {v[0]}" for k, v in takes.items()},
           "foreign_frames": sum(v[1] for k, v in takes.items() if tj["videos"].get(k, 0) is None)}
    e = errors_against_truth(cams, recs, tj, office)
    if e is not None:
        out.update({"rotation_deg_median": round(e["rotation_deg_median"], 2),
                    "rotation_deg_max": round(e["rotation_deg_max"], 2),
                    "over_5_deg": int(sum(r > 5 for r in e["rotation_deg"]))})
    return out


def errors_against_truth(cams, recs: list[dict], tj: dict, office: Path | None) -> dict | None:
    """:func:`research.align.pose_errors` of ``cams`` (a model's cameras, named by working name) against
    the case's truth (``tj``: a ``<case>.truth.json``; office cases need ``office``); ``recs``: the kept
    records of ``images.json``. None under 3 frames with a truth."""
    from curate.core.cameras import Cameras
    from research.align import pose_errors
    from research.datasets import load_office
    truth = Cameras.load(tj["cameras"]) if tj.get("cameras") else load_office(office)
    gt_of = truth_of(recs, tj)
    keep = [i for i, nm in enumerate(cams.names) if nm in gt_of]
    if len(keep) < 3:
        return None
    sub = cams[keep]
    est = Cameras(sub.c2w, sub.fx, sub.fy, sub.cx, sub.cy, sub.width, sub.height,
                  names=tuple(truth.names[gt_of[nm]] for nm in sub.names))
    return pose_errors(est, truth)


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("make", help="write the test captures")
    m.add_argument("--office", type=Path, required=True)
    m.add_argument("--fox", type=Path, required=True)
    m.add_argument("--out", type=Path, required=True)
    m.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES)
    e = sub.add_parser("eval", help="how a run's SfM kept each take")
    e.add_argument("run", type=Path)
    e.add_argument("--truth", type=Path, default=None, help="<case>.truth.json written by make")
    e.add_argument("--office", type=Path, default=None)
    e.add_argument("--global-model", action="store_true",
                   help="also map the matches with COLMAP's global mapper and judge its model against the truth")
    a = ap.parse_args(argv)
    if a.cmd == "make":
        res = {k: {"videos": {v: (len(f) if f else "no truth") for v, f in c["videos"].items()},
                   "photos": len(c["photos"])} for k, c in make(a.office, a.fox, a.out, tuple(a.cases)).items()}
    else:
        res = evaluate(a.run, a.truth, a.office)
        if a.global_model and a.truth is not None:
            res["global_model"] = global_model(a.run, a.truth, a.office)
    print(json.dumps(res))
    return res


if __name__ == "__main__":
    main()
