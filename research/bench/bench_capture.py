#!/usr/bin/env python
"""Benchmark curate on long captures: SfM and the stages after it against the pool size.

    python3 -m research.bench.bench_capture --lengths 250 500 1000 [--office ../shared/data/office]

Renders one long hand-held walk (:func:`curate.simulate.walks.hand_held_walk`) through a
synthetic room of :mod:`curate.simulate.synthetic` (640x480, 10 frames a second, hand
shake, motion blur in proportion to the turning speed), once, into H.264 videos of its
first N frames for each N of ``--lengths`` (cached under ``--work``). For each video (and
``office.mp4`` with ``--office``) it runs, each in its own process,

    curate sfm VIDEO --out RUN                        # decode, candidates, COLMAP
    curate run VIDEO --out RUN --budget B --no-evaluate  # SfM reused: occupancy, select, export, report

and records each stage's seconds (from ``RUN/*/stage.json``), each process's peak resident
memory, the frames decoded / kept as candidates / registered, the models' sizes, and the
median rotation and relative centre errors of the registered frames against the rendered
poses (or ``poses.txt``) after a similarity alignment. Prints one JSON line per capture
and, as the LAST line, ``{"captures": [...]}``; ``--plot FILE`` draws seconds against
pool size per stage.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

FPS = 10.0
EXPOSURE_S = 1 / 120
"""Shutter time of the rendered video: motion blur = angular speed x exposure x focal length, in pixels."""


def _render_chunk(args):
    """Rendered uint8 frames [k, H, W, 3] of cameras ``idx`` of the walk (in a worker process)."""
    layout, seed, n, kind, idx = args
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk, motion_blur
    scene = make_scene(layout, seed)
    cams, omega = hand_held_walk(n, kind, seed=seed, room=scene.interior, fps=FPS)
    out = []
    for i in idx:
        rgb, _ = scene.render(cams[int(i)])
        out.append(motion_blur(rgb[0], omega[i], float(cams.fx[i]), FPS * EXPOSURE_S))
    return idx, out


def render_videos(work: Path, lengths: list[int], layout: str, kind: str, seed: int, jobs: int) -> dict:
    """{N: path of the video of the walk's first N frames}; the walk has max(lengths) frames; cached."""
    import av
    from multiprocessing import Pool

    from curate.simulate.walks import hand_held_walk
    n = max(lengths)
    tag = f"{layout}_{kind}_s{seed}_n{n}"
    paths = {k: work / f"walk_{tag}_{k}.mp4" for k in lengths}
    meta = work / f"walk_{tag}.json"
    if meta.is_file() and all(p.is_file() for p in paths.values()):
        return paths
    work.mkdir(parents=True, exist_ok=True)
    cams, _ = hand_held_walk(n, kind, seed=seed, fps=FPS)
    np.save(work / f"walk_{tag}_c2w.npy", cams.c2w)
    t = time.perf_counter()
    conts, streams = {}, {}
    for k, p in paths.items():
        conts[k] = av.open(str(p) + ".part", mode="w", format="mp4")
        s = conts[k].add_stream("libx264", rate=int(FPS))
        s.width, s.height, s.pix_fmt = int(cams.width[0]), int(cams.height[0]), "yuv420p"
        s.options = {"crf": "18", "preset": "medium"}
        streams[k] = s
    chunks = [(layout, seed, n, kind, list(range(a, min(a + 20, n)))) for a in range(0, n, 20)]
    done = 0
    with Pool(jobs) as pool:
        for idx, frames in pool.imap(_render_chunk, chunks):
            for i, rgb in zip(idx, frames):
                vf = av.VideoFrame.from_ndarray(rgb, format="rgb24")
                for k in lengths:
                    if i < k:
                        for pkt in streams[k].encode(vf):
                            conts[k].mux(pkt)
            done += len(idx)
            print(f"rendered {done}/{n} frames ({time.perf_counter() - t:.0f} s)", file=sys.stderr, flush=True)
    for k in lengths:
        for pkt in streams[k].encode():
            conts[k].mux(pkt)
        conts[k].close()
        os.replace(str(paths[k]) + ".part", paths[k])
    meta.write_text(json.dumps({"layout": layout, "kind": kind, "seed": seed, "frames": n, "fps": FPS,
                                "render_seconds": round(time.perf_counter() - t, 1)}))
    return paths


def _timed(cmd: list[str]) -> dict:
    """Run ``cmd``; its seconds, exit code and peak resident memory (MB, the process and its children)."""
    t = time.perf_counter()
    p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    err_lines = []
    for line in p.stderr:
        err_lines.append(line)
    _, status, ru = os.wait4(p.pid, 0)
    p.returncode = os.waitstatus_to_exitcode(status)
    return {"seconds": round(time.perf_counter() - t, 1), "rc": p.returncode,
            "peak_rss_mb": round(ru.ru_maxrss / 1024, 1), "stderr_tail": "".join(err_lines[-3:]).strip()}


def _truth_cameras(video: Path, work: Path):
    """Ground-truth Cameras of a rendered walk video (frame i named ``frame_{i:05d}``)."""
    from curate.core.cameras import Cameras
    tag = video.stem.rsplit("_", 1)[0].removeprefix("walk_")
    c2w = np.load(work / f"walk_{tag}_c2w.npy")
    return Cameras(c2w, 554.0, 554.0, 320.0, 240.0, 640, 480, names=tuple(f"frame_{i:05d}" for i in range(len(c2w))))


def measure(video: Path, run: Path, budget_fraction: float, truth=None, force: bool = False) -> dict:
    """Run SfM and then the rest with ``--no-evaluate`` on ``video``; the JSON-able record."""
    import shutil

    from curate.sfm.io import load_sfm
    from research.align import pose_errors
    from research.sfm_mappers import truth_for
    if force and run.exists():
        shutil.rmtree(run)
    cur = [sys.executable, "-m", "curate"]
    rec: dict = {"capture": video.name}
    rec["sfm_process"] = _timed(cur + ["sfm", str(video), "--out", str(run)])
    if rec["sfm_process"]["rc"] != 0:
        rec["error"] = rec["sfm_process"]["stderr_tail"]
        return rec
    st = json.loads((run / "sfm" / "stage.json").read_text())
    stats = st["stats"]
    recs = json.loads((run / "sfm" / "images.json").read_text()).get("photos", [])
    n_kept = stats.get("n_kept")
    rec.update({"n_kept": n_kept, "n_registered": stats.get("n_registered"),
                "registered_fraction": stats.get("registered_fraction"), "model_sizes": stats.get("model_sizes"),
                "sfm_timings": st.get("timings"), "sfm_seconds": st.get("seconds")})
    vids = stats.get("videos") or []
    rec["frames_decoded"] = sum(v.get("decoded", 0) for v in vids) or None
    rec["frames_candidates"] = sum(v.get("candidates", 0) for v in vids) or None
    budget = max(2, int(round(budget_fraction * (stats.get("n_registered") or 0))))
    rec["budget"] = budget
    rec["after_sfm_process"] = _timed(cur + ["run", str(video), "--out", str(run), "--budget", str(budget),
                                             "--no-evaluate"])
    rec["after_sfm_stages"] = {}
    rep = json.loads((run / "report.json").read_text()) if (run / "report.json").is_file() else {}
    for t in rep.get("stages") or []:       # this invocation's stages (sfm reused), as report.json lists them
        if t.get("name") != "sfm":
            rec["after_sfm_stages"][t["name"]] = t.get("seconds")
    if truth is not None:
        frame_of = {r["working"]: r["extra"]["frame"] for r in recs if (r.get("extra") or {}).get("video")}
        cams = load_sfm(run).cameras
        e = pose_errors(*truth_for(cams, truth, frame_of))
        rec.update({k: e[k] for k in ("n_matched", "rotation_deg_median", "rotation_deg_max", "centre_rel_median")})
        rec["registered_of_frames_in_truth"] = round(e["n_matched"] / max(n_kept or 1, 1), 4)
    return rec


def plot(records: list[dict], path: Path) -> None:
    """Seconds against pool size, per stage (SfM's extract / match / map and the stages after it)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    records = [r for r in records if "error" not in r]
    walks = sorted((r for r in records if r["capture"].startswith("walk_")), key=lambda r: r["n_kept"])
    if not walks:
        return
    x = [r["n_kept"] for r in walks]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for key in ("extract", "match", "map"):
        ax.plot(x, [r["sfm_timings"].get(key, 0) for r in walks], "o-", label=f"SfM {key}")
    ax.plot(x, [r["sfm_seconds"] for r in walks], "s-", color="k", label="SfM total")
    ax.plot(x, [sum(v or 0 for v in r["after_sfm_stages"].values()) for r in walks], "^-",
            label="after SfM (--no-evaluate)")
    for r in records:
        if not r["capture"].startswith("walk_"):
            ax.plot([r["n_kept"]], [r["sfm_seconds"]], "D", color="tab:red", label=f"SfM total, {r['capture']}")
    ax.set_xlabel("candidate frames given to SfM")
    ax.set_ylabel("seconds (2-core CPU)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--lengths", type=int, nargs="*", default=[250, 500, 1000], help="frames of each walk video")
    ap.add_argument("--layout", default="livingroom", help="synthetic room (livingroom, office, kitchen)")
    ap.add_argument("--kind", default="loop", help="kind of walk (curate.simulate.walks.WALK_KINDS)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--office", type=Path, default=None, help="also office.mp4 of this folder (poses.txt: truth)")
    ap.add_argument("--work", type=Path, default=Path("/tmp/curate_bench_capture"), help="videos and run folders")
    ap.add_argument("--budget-fraction", type=float, default=0.15, help="budget of the --no-evaluate run")
    ap.add_argument("--jobs", type=int, default=2, help="rendering processes")
    ap.add_argument("--force", action="store_true", help="run again (videos stay cached)")
    ap.add_argument("--plot", type=Path, default=None, help="PNG of seconds against pool size")
    a = ap.parse_args(argv)
    records = []
    if a.lengths:
        videos = render_videos(a.work / "videos", sorted(a.lengths), a.layout, a.kind, a.seed, a.jobs)
        for n, v in sorted(videos.items()):
            truth = _truth_cameras(v, a.work / "videos")
            r = measure(v, a.work / "runs" / v.stem, a.budget_fraction, truth, a.force)
            r["frames_rendered"] = n
            records.append(r)
            print(json.dumps(r), flush=True)
    if a.office is not None:
        from research.datasets import load_ground_truth
        r = measure(a.office / "office.mp4", a.work / "runs" / "office_mp4", a.budget_fraction,
                    load_ground_truth(a.office), a.force)
        records.append(r)
        print(json.dumps(r), flush=True)
    if a.plot and records:
        plot(records, a.plot)
    print(json.dumps({"captures": records}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
