"""Do ``curate suggest``'s poses improve a deficient capture more than random feasible poses or more of the same walk?

Issue 37's validation, in the synthetic rooms of :mod:`curate.simulate.synthetic`, where any view can be rendered.
Per room (livingroom, office, kitchen) and deficiency:

* ``corner``: a hand-held loop (:func:`curate.simulate.walks.hand_held_walk`) stopped at :data:`CORNER_SHARE` of
  a lap: the last corner of the room is skipped;
* ``turn``: standing at one spot and turning on it (the first spot of the ``turn`` walk, before it walks on);
* ``corridor``: a pass back and forth along the room's long side (:data:`CORRIDOR_FRAMES` frames).

The deficient capture is rendered (:data:`SIZE`, 5 frames a second) and made a run folder as ``curate run
PHOTOS --no-evaluate`` makes it after SfM: its known poses imported, with stand-ins for its SfM points
(:func:`sfm_points`: random pixels back-projected with the renderer's depth, 1 cm of noise), from which the
occupancy stage builds the occupancy as for a real capture. ``curate suggest --add K`` is run on it with its
defaults and places K poses. Then the same field (:class:`curate.field.model.FieldConfig` defaults, ``--iters``
iterations, one seed, one box: the capture's :func:`curate.field.train.default_box`) is trained on

* ``base``: the deficient capture alone;
* ``suggest``: the capture + the K suggested poses (rendered);
* ``random``: the capture + K poses drawn uniformly among the *same* feasible poses the suggestions were
  chosen from (``--random-draws`` draws, each view's PSNR averaged over them);
* ``continue``: the capture + K frames evenly spaced along the walk's own continuation (the next half of the
  capture's length, the same trajectory generator): what filming on the same way gives;
* ``full``: the capture + one whole hand-held loop of the room (:data:`FULL_FRAMES`): a complete re-shoot
  (``--full-scaled``: also ``full_scaled``, the same photos trained for as many iterations per photo as the
  suggest arm gets, so that the longer capture is not short of training).

Every field is scored on the same :data:`N_TEST` free-viewpoint test views per room, drawn at random in the
room's free space off every path (the harness's protocol: centre free, nothing nearer than 0.3 m, pitch within
45 degrees). Paired per test view: suggest - random, suggest - continue (95% t intervals); gap closed:
``(suggest - base) / (full - base)`` of the mean PSNRs (and the same for the alternatives).

Results are cached per arm under ``--out`` (a re-run resumes). Prints a markdown table and one JSON line last.

Usage (CPU, about 10 minutes a cell on a quiet 2-core machine):
  nice -n 10 python3 -m research.suggest_eval --out /tmp/suggest_eval
  python3 -m research.suggest_eval --rooms kitchen --deficiencies turn --add 10 --iters 500
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from dataclasses import replace

import numpy as np

ROOMS = ("livingroom", "office", "kitchen")
DEFICIENCIES = ("corner", "turn", "corridor")
SIZE = (160, 120)
"""Rendered and trained image size (60 degree horizontal field of view)."""
FPS = 5.0
CORNER_SHARE = 0.72
"""``corner``: the share of one lap walked."""
CORRIDOR_FRAMES = 80
TURN_SPOTS = 3
N_TEST = 40
FULL_FRAMES = 140
POINTS_PER_FRAME = 300
ARMS = ("base", "suggest", "random", "continue", "full")


def lap_frames(world) -> int:
    """Frames of one lap of the ``loop`` walk in ``world`` (its radius is 0.55 of the mean half extent)."""
    lo, hi = world.interior
    half = (np.asarray(hi) - np.asarray(lo)) / 2
    return int(np.ceil(2 * np.pi * 0.55 * np.mean(half[:2]) / (0.35 / FPS)))


def deficient_walk(world, kind: str, seed: int):
    """(base capture, its continuation) of deficiency ``kind`` in ``world`` (module docstring)."""
    from curate.simulate.walks import hand_held_walk
    kw = dict(seed=seed, width=SIZE[0], height=SIZE[1], fps=FPS, room=world.interior)
    if kind == "corner":
        n = int(round(CORNER_SHARE * lap_frames(world)))
        walk, _ = hand_held_walk(n + n // 2 + 1, "loop", **kw)
    elif kind == "turn":
        total = 3 * 80
        n = int(0.85 * total / TURN_SPOTS)                 # the first spot, before walking to the next
        walk, _ = hand_held_walk(total, "turn", **kw)
    elif kind == "corridor":
        n = CORRIDOR_FRAMES
        walk, _ = hand_held_walk(n + n // 2 + 1, "corridor", **kw)
    else:
        raise SystemExit(f"unknown deficiency {kind!r}: one of {DEFICIENCIES}")
    return walk[:n], walk[n:n + n // 2 + 1]


def test_views(world, n: int, seed: int = 7):
    """``n`` free-viewpoint test cameras: the harness's off-path protocol (research.harness.walk_scene)."""
    from curate.simulate.progressive import CameraSpec, ProgressiveConfig, draw_acceptable, scene_oracle
    lo, hi = world.interior
    pc = ProgressiveConfig(camera=CameraSpec(SIZE[0], SIZE[1], 60.0))
    return draw_acceptable(np.random.default_rng(seed), lo + 0.05, hi - 0.05, n, pc, *scene_oracle(world))


def render(world, cams, depth: bool = False):
    """[N] uint8 images (and [N] z-depth maps with ``depth``) of ``cams`` in ``world``."""
    out = [world.render(cams[i]) for i in range(len(cams))]
    rgb = [o[0][0] for o in out]
    return (rgb, [o[1][0] for o in out]) if depth else rgb


def sfm_points(cams, depths, per_frame: int = POINTS_PER_FRAME, noise: float = 0.01, seed: int = 0) -> np.ndarray:
    """[P, 3] stand-ins for a capture's SfM points: ``per_frame`` random image points of each frame back-projected
    with the renderer's depth of the pixel each falls in, plus Gaussian noise of ``noise`` (what COLMAP
    triangulates on these textured surfaces, without its outliers)."""
    rng = np.random.default_rng(seed)
    out = []
    for k, z in enumerate(depths):
        h, w = z.shape
        u, v = rng.uniform(0, w, per_frame), rng.uniform(0, h, per_frame)
        zz = z[v.astype(int), u.astype(int)].astype(float)
        ok = np.isfinite(zz) & (zz > 0)
        xc = np.stack([(u - cams.cx[k]) / cams.fx[k] * zz, (v - cams.cy[k]) / cams.fy[k] * zz, zz], 1)[ok]
        out.append(xc @ cams.rotations[k].T + cams.centres[k])
    p = np.concatenate(out)
    return (p + rng.normal(0, noise, p.shape)).astype(np.float32)


def train_eval(cams, imgs, tests, test_imgs, box, iters: int, seed: int = 0) -> list[float]:
    """Per-test-view PSNR of the field trained on (cams, imgs)."""
    from curate.field.metrics import evaluate
    from curate.field.model import FieldConfig
    from curate.field.train import train_field
    fld, _ = train_field(FieldConfig(), cams, imgs, iters=iters, seed=seed, box=box)
    return [v["psnr"] for v in evaluate(fld, tests, test_imgs)["per_view"]]


def make_run(base, imgs, depths, d: Path) -> Path:
    """A run folder of the capture, as ``curate run PHOTOS --no-evaluate`` makes it after SfM: the known poses
    imported, with :func:`sfm_points` as its sparse points (the occupancy comes from them, as for a real capture)."""
    from PIL import Image
    from curate.config import RunConfig
    from curate.core.transforms_json import write_transforms
    from curate.pipeline import run as pipeline
    cap = d / "capture"
    run = d / "run"
    if (run / "select" / "stage.json").is_file():
        return run
    (cap / "images").mkdir(parents=True, exist_ok=True)
    rel = [f"images/frame_{i:04d}.png" for i in range(len(base))]
    for r, im in zip(rel, imgs):
        Image.fromarray(im).save(cap / r)
    write_transforms(cap / "transforms.json", base, rel)
    cfg = RunConfig(budget="15%", run_evaluation=False)
    pipeline(cfg, cap, run, poses=cap / "transforms.json", until="sfm")
    np.save(run / "sfm" / "points.npy", sfm_points(base, depths))
    pipeline(cfg, cap, run, poses=cap / "transforms.json", until="select")     # sfm: unchanged, skipped
    return run


def poses_tag(cams) -> str:
    """A short hash of an arm's added poses (None: the capture alone), so a cached arm is reused only for them."""
    import hashlib
    if cams is None:
        return "none"
    return hashlib.sha1(np.round(cams.c2w, 6).tobytes()).hexdigest()[:12]


def cell(room: str, kind: str, out: Path, args) -> dict:
    """Every arm of one (room, deficiency) cell; cached per arm in ``out/<room>-<kind>/arms``."""
    from curate.core import runfolder
    from curate.core.cameras import Cameras
    from curate.field.train import default_box
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk
    from curate.suggest.config import SuggestConfig
    from curate.suggest import stage as sst

    d = out / f"{room}-{kind}"
    arms_dir = d / "arms"
    arms_dir.mkdir(parents=True, exist_ok=True)
    world = make_scene(room, seed=0)
    base, cont_pool = deficient_walk(world, kind, args.walk_seed)
    tests = test_views(world, N_TEST)
    t0 = time.perf_counter()
    test_imgs = [im.astype(np.float32) / 255 for im in render(world, tests)]
    base_imgs, base_depths = render(world, base, depth=True)
    run = make_run(base, base_imgs, base_depths, d)
    cfg = SuggestConfig(add=args.add, seed=args.seed, nodes=args.nodes)
    t1 = time.perf_counter()
    with runfolder.claimed(run, must_exist=True):
        res = sst.run(cfg, run, force=True, progress=False)   # always this code's suggestions
    rec = json.loads((run / "suggest" / "suggestions.json").read_text())
    sugg = Cameras(np.array([s["c2w"] for s in rec["suggestions"]]), *rec["envelope"]["intrinsics"])
    # the feasible set the suggestions were drawn from, for the random arm (same field, same envelope)
    inp = sst.read_run(run)
    assert inp.occupancy_usable(), f"{run}: the occupancy from the points is not usable"
    pl, feas, *_ = sst.suggest(cfg, inp)
    assert np.allclose(pl.cams.c2w, sugg.c2w), "the stage's suggestions differ from a re-run of its computation"
    suggest_s = time.perf_counter() - t1
    randoms = [feas.draw(np.random.default_rng(1000 + r), args.add) for r in range(args.random_draws)]
    idx = np.unique(np.linspace(0, len(cont_pool) - 1, args.add).round().astype(int))
    cont = cont_pool[idx]
    full, _ = hand_held_walk(FULL_FRAMES, "loop", seed=args.walk_seed + 100, width=SIZE[0], height=SIZE[1], fps=FPS,
                             room=world.interior)
    box = default_box(base)                  # one box for every arm: the capture's
    extra = {"suggest": [sugg], "random": randoms, "continue": [cont], "full": [full], "base": [None]}
    arms = list(ARMS)
    if args.frontier_arm:   # the same placement over the surface and the frontier of the observed free space
        pl2 = sst.suggest(replace(cfg, nodes="surface+frontier"), inp)[0]
        extra["frontier"] = [pl2.cams]
        arms.append("frontier")
    if args.full_scaled:    # the full capture with as many passes over each photo as the suggest arm gets
        extra["full_scaled"] = [full]
        arms.append("full_scaled")
    iters = {a: args.iters for a in arms}
    iters["full_scaled"] = int(round(args.iters * (len(base) + len(full)) / (len(base) + len(sugg))))
    per_arm: dict[str, list[list[float]]] = {}
    for arm in arms:
        per_arm[arm] = []
        for r, add in enumerate(extra[arm]):
            f = arms_dir / f"{arm}_{r}.json"
            tag = poses_tag(add)
            if f.is_file() and not args.retrain:
                rec_arm = json.loads(f.read_text())
                if rec_arm.get("poses") == tag:          # the same added photos: the cached result stands
                    per_arm[arm].append(rec_arm["psnr"])
                    continue
                print(f"  {room}-{kind} {arm}[{r}]: its added poses changed: retraining", flush=True)
            cams = base if add is None else Cameras.concat([base, add])
            imgs = base_imgs + ([] if add is None else render(world, add))
            ts = time.perf_counter()
            psnr = train_eval(cams, imgs, tests, test_imgs, box, iters[arm], args.seed)
            f.write_text(json.dumps({"psnr": psnr, "poses": tag, "n_train": len(cams), "iters": iters[arm],
                                     "seconds": time.perf_counter() - ts}))
            per_arm[arm].append(psnr)
            print(f"  {room}-{kind} {arm}[{r}]: {np.mean(psnr):.2f} dB ({len(cams)} views, "
                  f"{time.perf_counter() - ts:.0f}s)", flush=True)
    lo, hi = world.interior
    bad = world.occupied(sugg.centres)
    return {"room": room, "deficiency": kind, "n_base": len(base), "add": args.add,
            "psnr": {a: np.mean(v, axis=0).tolist() for a, v in per_arm.items()},
            "suggest_inside_solid": int(bad.sum()), "suggest_timing": rec["timing"],
            "energy_before": rec["energy_before"], "energy_after": rec["energy"][-1],
            "suggest_seconds": suggest_s, "render_seconds": t1 - t0, "stage_summary": res.summary}


def summarise(c: dict) -> dict:
    """Paired differences and gaps closed of one cell."""
    from curate.core.stats import paired_difference
    p = {a: np.asarray(v) for a, v in c["psnr"].items()}
    m = {a: float(v.mean()) for a, v in p.items()}
    gap = m["full"] - m["base"]
    r = lambda x: round(float(x), 3)  # noqa: E731
    out = {"room": c["room"], "deficiency": c["deficiency"], "n_base": c["n_base"], "add": c["add"],
           "mean": {a: r(v) for a, v in m.items()}}
    for o in ("random", "continue", "base"):
        d = paired_difference(p["suggest"], p[o])
        out[f"suggest-{o}"] = {k: (r(v) if isinstance(v, float) else v) for k, v in d.items()}
    if "frontier" in p:
        for o in ("random", "continue", "suggest"):
            d = paired_difference(p["frontier"], p[o])
            out[f"frontier-{o}"] = {k: (r(v) if isinstance(v, float) else v) for k, v in d.items()}
    out["gap_closed"] = {a: (r((m[a] - m["base"]) / gap) if gap > 1e-6 else None)
                         for a in ("suggest", "random", "continue", "frontier") if a in m}
    if "full_scaled" in m:      # against the full capture trained as long per photo as the suggest arm
        gs = m["full_scaled"] - m["base"]
        out["gap_closed_scaled"] = {a: (r((m[a] - m["base"]) / gs) if gs > 1e-6 else None)
                                    for a in ("suggest", "random", "continue", "frontier") if a in m}
    out["beats_both"] = bool(out["suggest-random"]["lo"] > 0 and out["suggest-continue"]["lo"] > 0)
    out["suggest_inside_solid"] = c["suggest_inside_solid"]
    out["ms_per_camera"] = r(c["suggest_timing"]["ms_per_camera"])
    out["ms_per_candidate"] = r(c["suggest_timing"]["ms_per_candidate"])
    return out


def table(rows: list[dict]) -> str:
    """Markdown table of the summaries (columns for the optional arms only when a row has them)."""
    ci = lambda d: f"{d['mean']:+.2f} ({d['lo']:+.2f} to {d['hi']:+.2f})"  # noqa: E731
    fr = any("frontier" in s["mean"] for s in rows)
    fs = any("full_scaled" in s["mean"] for s in rows)
    cols = ["room", "deficiency", "base frames", "base", "+ suggested", "+ random feasible", "+ continued path", "full"]
    cols += ["full, scaled iterations"] if fs else []
    cols += ["+ suggested, frontier nodes"] if fr else []
    cols += ["suggest − random (95% CI)", "suggest − continue (95% CI)"]
    cols += ["frontier − suggest (95% CI)"] if fr else []
    cols += ["gap closed: suggest / random / continue"]
    cols += ["gap closed, scaled full"] if fs else []
    lines = ["| " + " | ".join(cols) + " |", "|" + "|".join(["---"] * len(cols)) + "|"]
    g3 = lambda g: " / ".join("—" if g.get(a) is None else f"{g[a]:.2f}" for a in ("suggest", "random", "continue"))  # noqa: E731
    num = lambda m, a: f"{m[a]:.2f}" if a in m else "—"  # noqa: E731
    for s in rows:
        m = s["mean"]
        cells = [s["room"], s["deficiency"], str(s["n_base"]), num(m, "base"), num(m, "suggest"), num(m, "random"),
                 num(m, "continue"), num(m, "full")]
        cells += [num(m, "full_scaled")] if fs else []
        cells += [num(m, "frontier")] if fr else []
        cells += [ci(s["suggest-random"]), ci(s["suggest-continue"])]
        cells += [ci(s["frontier-suggest"]) if "frontier-suggest" in s else "—"] if fr else []
        cells += [g3(s["gap_closed"])]
        cells += [g3(s["gap_closed_scaled"]) if "gap_closed_scaled" in s else "—"] if fs else []
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rooms", default=",".join(ROOMS))
    ap.add_argument("--deficiencies", default=",".join(DEFICIENCIES))
    ap.add_argument("--add", type=int, default=10, help="poses added by every arm (K)")
    ap.add_argument("--iters", type=int, default=500, help="training iterations of every field")
    ap.add_argument("--random-draws", type=int, default=2)
    ap.add_argument("--nodes", default="surface", choices=("surface", "surface+frontier"),
                    help="curate suggest's --nodes")
    ap.add_argument("--frontier-arm", action="store_true", help="also the suggestions with --nodes surface+frontier "
                    "(arm 'frontier')")
    ap.add_argument("--full-scaled", action="store_true", help="also the full capture trained for as many passes "
                    "per photo as the suggest arm (arm 'full_scaled': iterations x its photos / the suggest arm's)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the trainings and of curate suggest")
    ap.add_argument("--walk-seed", type=int, default=1)
    ap.add_argument("--retrain", action="store_true", help="ignore cached arms")
    ap.add_argument("--out", default="/tmp/suggest_eval")
    args = ap.parse_args(argv)
    import logging
    logging.basicConfig(level=logging.WARNING)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    rows = []
    for kind in [k for k in args.deficiencies.split(",") if k]:         # every room of a deficiency first
        for room in [r for r in args.rooms.split(",") if r]:
            c = cell(room, kind, out, args)
            (out / f"{room}-{kind}" / "cell.json").write_text(json.dumps(c))
            s = summarise(c)
            rows.append(s)
            print(table([s]).splitlines()[-1], flush=True)
    print()
    print(table(rows))
    rooms_won = sorted({s["room"] for s in rows if s["beats_both"]})
    print(f"\nsuggest beats both alternatives (both 95% CIs above 0) in {sum(s['beats_both'] for s in rows)} of "
          f"{len(rows)} cells, in {len(rooms_won)} room(s): {', '.join(rooms_won) or 'none'}")
    settings = {k: v for k, v in vars(args).items() if k != "out"}
    print(json.dumps({"settings": {**settings, "size": SIZE, "fps": FPS, "n_test": N_TEST, "full_frames": FULL_FRAMES},
                      "rows": rows, "seconds": round(time.perf_counter() - t0, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
