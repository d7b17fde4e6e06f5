"""Does the same capture give the same model every run? (issue 58)

``make`` writes harder versions of ``office/office.mp4`` under ``OUT`` (each with a ``<case>.truth.json`` beside
it, as :mod:`research.takes` writes them: each video's frames to office frames):

* ``half``: every 2nd frame (187 frames); ``third``: every 3rd frame (125 frames);
* ``cut``: the second of frames (10) around the walk's fastest turn removed (the turn's angular speed from
  the ground truth);
* ``blur``: motion blur, each frame the mean of its neighbours over a window that grows with the camera's
  angular speed there (3 frames, 7 at the fastest fifth of the walk);
* ``half_cut``: every 2nd frame with the fastest turn's second removed;
* ``takes``: two takes (:func:`research.takes.make`'s ``two_takes``: the second played backwards,
  overlapping the first over 100 frames).

``run`` runs the SfM stage ``--runs`` times on each capture, each in a fresh run folder, with a checkout's code
(``--code``: the folder whose ``curate`` package is imported; the project's by default) and ``--threads``, and
appends one JSON line per run to ``--log``: the registered frames (and their hash), the models, the mapper,
the time of each stage, the poses' centres and rotations, and the errors against the ground truth.

``table`` reads such logs and prints, per capture and code, the runs, the distinct registered sets, the
registered counts, the largest pose difference between runs (after one similarity alignment) and the
stage times.

    python3 -m research.flip make --office ../shared/data/office --fox ../shared/data/fox --out /tmp/flip
    python3 -m research.flip run /tmp/flip --cases half cut --runs 5 --log /tmp/flip/after.jsonl
    python3 -m research.flip run /tmp/flip --cases half --runs 1 --label lin8 --log L \
        --set sequential_quadratic=false sequential_overlap=8       # any SfmConfig field, as JSON
    python3 -m research.flip table /tmp/flip/before.jsonl /tmp/flip/after.jsonl
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

CASES = ("office", "half", "third", "cut", "blur", "half_cut", "takes")


def angular_speed(office: Path) -> np.ndarray:
    """[n] degrees between each office frame's true orientation and the next one's (the last repeated)."""
    from curate.core.cameras import rotation_angle_deg
    from research.datasets import load_office
    R = load_office(office).rotations
    d = np.array([float(rotation_angle_deg(R[i + 1] @ R[i].T)) for i in range(len(R) - 1)])
    return np.append(d, d[-1])


def fastest_second(speed: np.ndarray, fps: int = 10) -> int:
    """The first frame of the ``fps``-frame window whose summed turn is the largest."""
    s = np.convolve(speed, np.ones(fps), "valid")
    return int(np.argmax(s))


def _blurred(frames: list[np.ndarray], speed: np.ndarray) -> list[np.ndarray]:
    """Each frame the mean of its neighbours over 3 frames, 7 where the walk turns fastest (its top fifth)."""
    fast = speed >= np.percentile(speed, 80)
    out = []
    for i in range(len(frames)):
        h = 3 if fast[i] else 1
        lo, hi = max(0, i - h), min(len(frames), i + h + 1)
        out.append(np.mean(np.stack(frames[lo:hi]).astype(np.float32), 0).round().astype(np.uint8))
    return out


def make(office: Path, fox: Path, out: Path, cases=CASES) -> dict:
    from research.takes import _decode, make as make_takes, write_video
    frames = _decode(office / "office.mp4")
    n = len(frames)
    speed = angular_speed(office)
    t0 = fastest_second(speed)
    cut = [i for i in range(n) if not (t0 <= i < t0 + 10)]
    chosen = {"office": list(range(n)), "half": list(range(0, n, 2)), "third": list(range(0, n, 3)), "cut": cut,
              "half_cut": [i for i in range(0, n, 2) if i in set(cut)], "blur": list(range(n))}
    done = {}
    for case, idx in chosen.items():
        if case not in cases:
            continue
        src = _blurred(frames, speed) if case == "blur" else frames
        write_video([src[i] for i in idx], out / case / "walk.mp4")
        done[case] = {"videos": {"walk.mp4": idx}, "photos": {}, "fastest_second": t0}
        (out / f"{case}.truth.json").write_text(json.dumps(done[case]))
    if "takes" in cases:
        tk = make_takes(office, fox, out / "_takes", ("two_takes",))
        shutil.rmtree(out / "takes", ignore_errors=True)
        shutil.move(out / "_takes" / "two_takes", out / "takes")
        shutil.rmtree(out / "_takes")
        done["takes"] = tk["two_takes"]
        (out / "takes.truth.json").write_text(json.dumps(done["takes"]))
    return done


_RUN = r"""
import json, sys, time, logging
from pathlib import Path
logging.basicConfig(level=logging.WARNING)
from curate.sfm.config import SfmConfig
from curate.sfm.colmap import run_sfm
cfg = SfmConfig(progress=False, num_threads=int(sys.argv[3]), **json.loads(sys.argv[4]))
t = time.perf_counter()
try:
    run_sfm(cfg, sys.argv[1], sys.argv[2])
    print(json.dumps({"ok": True, "wall": time.perf_counter() - t}))
except Exception as e:
    print(json.dumps({"ok": False, "error": f"{type(e).__name__}: {e}", "wall": time.perf_counter() - t}))
"""


def one_run(capture: Path, run: Path, code: Path, threads: int, settings: dict | None = None) -> dict:
    """The SfM stage on ``capture`` in the fresh run folder ``run`` with the ``curate`` of ``code`` and the
    ``SfmConfig`` fields ``settings`` set."""
    shutil.rmtree(run, ignore_errors=True)
    env = dict(os.environ, PYTHONPATH=str(code))
    t = time.perf_counter()
    cpu0 = os.times()
    p = subprocess.run([sys.executable, "-c", _RUN, str(capture), str(run), str(threads),
                        json.dumps(settings or {})], env=env, cwd=code,
                       capture_output=True, text=True)
    cpu1 = os.times()
    res = json.loads(p.stdout.strip().splitlines()[-1]) if p.stdout.strip() else {"ok": False, "error": p.stderr[-500:]}
    res["cpu_s"] = round((cpu1.children_user - cpu0.children_user) + (cpu1.children_system - cpu0.children_system), 1)
    res["wall"] = round(time.perf_counter() - t, 1)
    return res


def describe(run: Path, truth_json: Path | None, office: Path | None) -> dict:
    """What ``RUN/sfm`` holds: registered frames, models, stage times, poses, errors against the truth."""
    from curate.sfm.io import load_sfm
    from research.takes import errors_against_truth
    sfm = run / "sfm"
    st = json.loads((sfm / "stage.json").read_text())
    stats = st.get("stats", {})
    cams = load_sfm(run).cameras
    names = sorted(cams.names)
    out = {"n_kept": stats.get("n_kept"), "n_registered": len(names), "model_sizes": stats.get("model_sizes"),
           "mapper": stats.get("mapper"), "mappers_tried": stats.get("mappers_tried"),
           "timings": st.get("timings"), "seconds": st.get("seconds"),
           "registered_hash": hashlib.sha1("\n".join(names).encode()).hexdigest()[:12], "registered": names,
           "n_pairs_verified": stats.get("n_pairs_verified"),
           "c2w": {n: np.round(cams.c2w[i, :3, :4], 6).tolist() for i, n in enumerate(cams.names)}}
    if truth_json is not None and truth_json.is_file():
        recs = [r for r in json.loads((sfm / "images.json").read_text())["photos"] if r["status"] == "kept"]
        e = errors_against_truth(cams, recs, json.loads(truth_json.read_text()), office)
        if e is not None:
            out.update(rotation_deg_median=round(e["rotation_deg_median"], 2),
                       rotation_deg_max=round(e["rotation_deg_max"], 2),
                       over_5_deg=int(sum(r > 5 for r in e["rotation_deg"])))
    return out


def small_angle_deg(M: np.ndarray) -> float:
    """The angle of the rotation ``M`` in degrees, exact near zero (2 asin(|M - I| / 2 sqrt 2)), where the trace's
    arccos loses its precision: matrices rounded to 6 decimals read as 0.07 deg apart by the trace."""
    return float(np.degrees(2 * np.arcsin(min(1.0, np.linalg.norm(M - np.eye(3)) / (2 * np.sqrt(2))))))


def pose_spread(runs: list[dict]) -> dict:
    """The largest difference of each common frame's pose between the first run and each other: the raw largest
    difference of their camera-to-world matrices, and, once the runs' frames are aligned (one rotation, from
    the frames' orientations; one similarity for the centres), the rotation in degrees and the centre as a share
    of the first run's extent."""
    from research.align import umeyama
    ref = runs[0]["c2w"]
    raw, worst_r, worst_c = 0.0, 0.0, 0.0
    for r in runs[1:]:
        common = sorted(set(ref) & set(r["c2w"]))
        if len(common) < 3:
            continue
        A = np.array([ref[n] for n in common])
        B = np.array([r["c2w"][n] for n in common])
        raw = max(raw, float(np.abs(A - B).max()))
        U, _, Vt = np.linalg.svd(np.einsum("kij,klj->il", A[:, :, :3], B[:, :, :3]))
        R = U @ np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))]) @ Vt       # A_rot ~ R B_rot
        worst_r = max(worst_r, max(small_angle_deg((R @ B[k, :, :3]) @ A[k, :, :3].T) for k in range(len(common))))
        s, Rc, t = umeyama(B[:, :, 3], A[:, :, 3])
        ext = float(np.linalg.norm(A[:, :, 3].max(0) - A[:, :, 3].min(0))) or 1.0
        worst_c = max(worst_c, float(np.linalg.norm(s * B[:, :, 3] @ Rc.T + t - A[:, :, 3], axis=1).max()) / ext)
    return {"c2w_max_abs": round(raw, 7), "rot_deg_max": round(worst_r, 4), "centre_max": round(worst_c, 5)}


def table(logs: list[Path]) -> list[dict]:
    rows: dict = {}
    for log in logs:
        for line in log.read_text().splitlines():
            r = json.loads(line)
            rows.setdefault((r["label"], r["case"], r.get("threads")), []).append(r)
    out = []
    for (label, case, threads), runs in sorted(rows.items(), key=lambda kv: (kv[0][1], kv[0][0], str(kv[0][2]))):
        ok = [r for r in runs if r.get("ok")]
        sets = sorted({r["registered_hash"] for r in ok})
        tm = {k: [r["timings"].get(k) for r in ok if r.get("timings")] for k in ("ingest", "extract", "match", "map")}
        out.append({"code": label, "case": case, "threads": threads, "runs": len(runs), "failed": len(runs) - len(ok),
                    "distinct_registered_sets": len(sets),
                    "registered": [r["n_registered"] for r in ok], "n_kept": sorted({r["n_kept"] for r in ok}),
                    "mappers": sorted({str(r.get("mapper")) for r in ok}),
                    "models": [r["model_sizes"] for r in ok][:3],
                    "rotation_deg_median": [r.get("rotation_deg_median") for r in ok],
                    "over_5_deg": [r.get("over_5_deg") for r in ok],
                    **({"spread": pose_spread(ok)} if len(ok) > 1 and len(sets) == 1 else {}),
                    "seconds_median": {k: (float(np.median([v for v in x if v is not None])) if any(
                        v is not None for v in x) else None) for k, x in tm.items()},
                    "wall_median": float(np.median([r["wall"] for r in runs])),
                    "cpu_s_median": float(np.median([r["cpu_s"] for r in runs]))})
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    m = sub.add_parser("make")
    m.add_argument("--office", type=Path, required=True)
    m.add_argument("--fox", type=Path, required=True)
    m.add_argument("--out", type=Path, required=True)
    m.add_argument("--cases", nargs="*", default=list(CASES), choices=CASES)
    r = sub.add_parser("run")
    r.add_argument("root", type=Path, help="the folder make wrote")
    r.add_argument("--cases", nargs="*", default=list(CASES))
    r.add_argument("--runs", type=int, default=5)
    r.add_argument("--threads", type=int, nargs="*", default=[-1])
    r.add_argument("--code", type=Path, default=Path(__file__).resolve().parents[1])
    r.add_argument("--label", default="after")
    r.add_argument("--log", type=Path, required=True)
    r.add_argument("--office", type=Path, default=Path(__file__).resolve().parents[2] / "shared/data/office")
    r.add_argument("--work", type=Path, default=None, help="run folders (default: ROOT/runs)")
    r.add_argument("--keep", action="store_true", help="keep each run folder (default: only the last)")
    r.add_argument("--set", nargs="*", default=[], metavar="FIELD=JSON",
                   help="SfmConfig fields for every run, e.g. sequential_quadratic=false sequential_overlap=8")
    t = sub.add_parser("table")
    t.add_argument("logs", type=Path, nargs="+")
    a = ap.parse_args(argv)
    if a.cmd == "make":
        res = {k: len(v["videos"]) for k, v in make(a.office, a.fox, a.out, tuple(a.cases)).items()}
        print(json.dumps(res))
    elif a.cmd == "run":
        work = a.work or a.root / "runs"
        settings = {k: json.loads(v) for k, v in (x.split("=", 1) for x in a.set)}
        for case in a.cases:
            capture = a.root / case if (a.root / case).exists() else Path(case)
            truth = a.root / f"{case}.truth.json"
            for threads in a.threads:
                for k in range(a.runs):
                    run = work / a.label / f"{case}_t{threads}_{k}"
                    res = one_run(capture, run, a.code, threads, settings)
                    row = {"label": a.label, "case": case, "threads": threads, "k": k, "settings": settings, **res}
                    if res.get("ok"):
                        row.update(describe(run, truth, a.office))
                    with open(a.log, "a") as f:
                        f.write(json.dumps(row) + "\n")
                    print(json.dumps({x: row.get(x) for x in ("label", "case", "threads", "k", "ok", "n_registered",
                                                               "model_sizes", "mapper", "wall", "registered_hash",
                                                               "timings", "rotation_deg_median", "error")}),
                          flush=True)
                    if not a.keep and k < a.runs - 1:
                        shutil.rmtree(run, ignore_errors=True)
    else:
        for row in table(a.logs):
            print(json.dumps(row))


if __name__ == "__main__":
    main()
