"""Which selection method gives the best NeRF? The evaluation harness of issue 7.

Per scene: a run folder under ``--out`` (known poses imported, no SfM; the occupancy stage
trains the pool field once, which is also the 'all' ceiling), then for each budget and
method a subset of the pool, and one field trained per (subset, training seed) with the
SAME :class:`curate.evaluate.units.EvalConfig` through :func:`curate.evaluate.units.run_units`
(units ``RUN/evaluate/q_<method>_b<budget>_t<seed>``, the default's folder named
``q_default-<hash of its SelectConfig and of auto's rule by kind of capture>_...``, keyed with
:func:`curate.core.stage.stage_key`, so a re-run skips finished trainings; a unit whose folder
holds another subset or settings, e.g. after a method's default changed, stops the run
unless ``--overwrite`` is given, so no earlier result is lost).

Scenes: office, fox, templering, skull (real captures, held-out views on the capture path)
and ``room``: a synthetic walk through the living room of :mod:`curate.simulate.synthetic`, rendered
once by the harness (:func:`room_scene`), whose fields are also scored on views drawn at
random in the room's free space, off the capture path (rows ``room-offpath``): the
free-viewpoint navigation the paper is about, which no real capture here can test.

Methods: ``default`` (curate's default, :class:`curate.select.config.SelectConfig`), ``energy``
(the paper), ``fvs`` (farthest-view sampling), ``random`` (n draws, one training
each; each hold-out fold draws its own, :func:`random_seed`), ``all`` (the pool field),
plus any ``--extra`` method of :data:`curate.select.methods.METHODS`, the variants of
:func:`_variants`, ``stride`` (every n-th frame in capture order) and
``oracle`` (not a method: it sees the held-out views; an upper bound on placement).

Hold-out folds (``--holdout-offsets``): fold o holds out images o, o + every, ...; with
several folds, a ``<scene>-folds`` table pools their held-out views (:func:`report_folds`).
``--holdout-blocks N:L:G`` holds out N contiguous blocks of L frames instead, with G frames
on each side left out of the pool (:func:`holdout_blocks`): a held-out view's nearest pool
frame is then at least G + 1 frames away, as when a user walks back through a room at
another time. Its unit folders have the same names: give it its own ``--out``.

Cheap proxies (seconds, no training) for every method: from each held-out view to the
chosen cameras, the nearest centre distance (``pos``, ``pos90``: mean, 90th percentile),
the smallest viewing-direction angle (``ang``, ``ang90``, degrees), the best
single-view overlap of its (node, direction-bin) cells (``cell``) and the nearest view in
view medoids' distance (``view``). ``r_loss``: the correlation, over the held-out views,
between what a subset loses against all the pool (PSNR) and ``view``. It only sees the
range of distances the subset leaves: near 0 for an even subset even where distance still
matters, which the ``oracle`` rows measure (a camera beside every held-out view).

Per-view paired differences (95% t intervals over the held-out views) of ``--candidate``
(default: ``default``) against random (averaged over its seeds per view), fvs, energy,
default, coverage, medoids, stride, oracle and all where present; each method's per-view PSNR
is first averaged over its training seeds.

The pool's pair index is built once per fold and shared by every method, so ``sel s`` /
``select_s`` is the selection alone, without the visibility it reads.

Prints a table per scene and budget, and ONE JSON line last; writes
``<out>/quality_psnr_<scenes>.svg`` (PSNR against budget per method, one chart per scene).

Usage:
  nice -n 5 python3 -m research.harness --scenes office --budgets 60 --train-seeds 2
  python3 -m research.harness --proxy-only --budgets 10%,17%,30%
  python3 -m research.harness --scenes office,fox,templering,skull --pack .gpudata/scenes
  python3 -m research.harness --data .gpudata/scenes --out .gpudata/quality ...  (e.g. on a GPU)
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared" / "data"
VARIANTS: dict = {}


# ------------------------------------------------------------------ scenes
SKULL_SFM = ROOT / "runs" / "skull"


def scene_cameras(scene: str):
    """(cameras, absolute image paths) of a scene: published or ground-truth poses; skull has
    none, so its cameras come from a ``curate sfm`` run folder (``--skull-sfm``)."""
    from research.datasets import load_office, load_templering
    from curate.core.transforms_json import read_transforms
    d = (SHARED / scene).resolve()
    if scene == "fox":
        return read_transforms(d / "transforms.json")
    if scene == "office":
        cams = load_office(d)
        return cams, [str(d / "images" / n) for n in cams.names]
    if scene == "templering":
        cams = load_templering(d)
        return cams, [str(d / n) for n in cams.names]
    if scene == "skull":
        from curate.sfm.io import image_paths
        from curate.sfm.io import load_sfm
        if not (SKULL_SFM / "sfm" / "cameras.json").is_file():
            raise SystemExit(f"skull has no poses: run `curate sfm {d}/images --out {SKULL_SFM}` first "
                             "(or pass --skull-sfm RUN)")
        sfm = load_sfm(SKULL_SFM)
        return sfm.cameras, image_paths(SKULL_SFM, list(sfm.cameras.names), sfm.records)
    raise SystemExit(f"unknown scene {scene!r}")


ROOM_WALK = (220, 80)
"""Scene "room": frames on the walk's loop and around the coffee table (a denser
``data_samples/room_walk`` walk: 300 frames instead of 160)."""
ROOM_OFFPATH = 40
"""Scene "room": random free-space test views off the walk (``curate simulate``'s random test set)."""


def room_scene(dest: Path) -> Path:
    """Render the synthetic "room" scene once into ``dest/room``: the walk's frames with a
    transforms.json (the pool and its on-path held-out views, as for a real capture) and
    ``offpath.json``, ``ROOM_OFFPATH`` views drawn at random in the room's free space (centre
    free, nothing nearer than 0.3 m, pitch within 45 deg): a test set off the capture path
    that only a synthetic scene has. Returns the transforms.json."""
    d = dest / "room"
    if (d / "transforms.json").is_file() and (d / "offpath.json").is_file():
        return d / "transforms.json"
    from curate.simulate.walks import room_walk
    from PIL import Image
    from curate.simulate.progressive import CameraSpec, ProgressiveConfig, draw_acceptable, scene_oracle
    from curate.simulate.synthetic import make_scene
    from curate.core.transforms_json import write_transforms
    scene = make_scene("livingroom", seed=0)
    walk = room_walk(*ROOM_WALK)
    lo, hi = scene.interior
    pc = ProgressiveConfig(camera=CameraSpec(int(walk.width[0]), int(walk.height[0]), 60.0))
    off = draw_acceptable(np.random.default_rng(7), lo + 0.05, hi - 0.05, ROOM_OFFPATH, pc, *scene_oracle(scene))
    (d / "images").mkdir(parents=True, exist_ok=True)
    for cams, stem, js in ((walk, "frame", "transforms.json"), (off, "offpath", "offpath.json")):
        rel = [f"images/{stem}_{i:04d}.jpg" for i in range(len(cams))]
        for i in range(0, len(cams), 20):
            for k, rgb in enumerate(scene.render(cams[i:i + 20])[0]):
                Image.fromarray(rgb).save(d / rel[i + k], quality=95)
        write_transforms(d / js, cams, rel)
    print(f"rendered room: {len(walk)} walk frames, {len(off)} off-path test views -> {d}")
    return d / "transforms.json"


WALK_FRAMES = 300
"""Scenes "walk-...": frames of each hand-held walk (10 a second, 320x240)."""
WALK_BLUR_EXPOSURE = 0.5
"""Scene "walk-blur": the shutter is open half of each frame (heavy motion blur when turning)."""


FAST_KINDS = ("blur", "fast")
"""Walk kinds beyond ``WALK_KINDS``: the loop twice as fast (walked twice in ``WALK_FRAMES``),
with motion blur (``blur``) or without (``fast``, the control that separates the two)."""


WALK_SEED = 1
"""Seed of a walk scene's trajectory unless its name gives one (``-s<seed>``)."""


def walk_spec(scene: str):
    """(kind, layout, blur, seed) of a synthetic walk scene ``walk-<kind>[-<layout>][-s<seed>]``
    (kinds: :data:`curate.simulate.walks.WALK_KINDS` and :data:`FAST_KINDS`; layouts:
    :data:`curate.simulate.synthetic.LAYOUTS`, default livingroom; seed: of the walk's
    trajectory, default :data:`WALK_SEED`), or None."""
    if not scene.startswith("walk-"):
        return None
    from curate.simulate.synthetic import LAYOUTS
    from curate.simulate.walks import WALK_KINDS
    parts = scene.split("-")[1:]
    seed = WALK_SEED
    if len(parts) > 1 and re.fullmatch(r"s\d+", parts[-1]):
        seed = int(parts.pop()[1:])
    kind, layout = parts[0], (parts[1] if len(parts) > 1 else "livingroom")
    if kind not in WALK_KINDS + FAST_KINDS or layout not in LAYOUTS or len(parts) > 2:
        raise SystemExit(f"unknown walk scene {scene!r}: "
                         f"walk-<{'|'.join(WALK_KINDS + FAST_KINDS)}>[-<{'|'.join(LAYOUTS)}>][-s<seed>]")
    return kind, layout, kind == "blur", seed


def walk_scene(dest: Path, scene: str) -> Path:
    """Render a synthetic walk scene (:func:`walk_spec`) once into ``dest/<scene>``, as
    :func:`room_scene` does: the walk's frames (transforms.json) and ``ROOM_OFFPATH``
    free-space test views off the path (offpath.json). Returns the transforms.json."""
    d = dest / scene
    if (d / "transforms.json").is_file() and (d / "offpath.json").is_file():
        return d / "transforms.json"
    from PIL import Image
    from curate.core.transforms_json import write_transforms
    from curate.simulate.progressive import CameraSpec, ProgressiveConfig, draw_acceptable, scene_oracle
    from curate.simulate.synthetic import make_scene
    from curate.simulate.walks import hand_held_walk, motion_blur
    kind, layout, blur, seed = walk_spec(scene)
    world = make_scene(layout, seed=0)
    fast = kind in FAST_KINDS
    walk, omega = hand_held_walk(WALK_FRAMES, "loop" if fast else kind, seed=seed, width=320, height=240,
                                 speed=0.7 if fast else 0.35, room=world.interior)
    lo, hi = world.interior
    pc = ProgressiveConfig(camera=CameraSpec(320, 240, 60.0))
    off = draw_acceptable(np.random.default_rng(7), lo + 0.05, hi - 0.05, ROOM_OFFPATH, pc, *scene_oracle(world))
    (d / "images").mkdir(parents=True, exist_ok=True)
    for cams, stem, js, om in ((walk, "frame", "transforms.json", omega), (off, "offpath", "offpath.json", None)):
        rel = [f"images/{stem}_{i:04d}.jpg" for i in range(len(cams))]
        for i in range(len(cams)):
            rgb = world.render(cams[i])[0][0]
            if blur and om is not None:
                rgb = motion_blur(rgb, om[i], float(cams.fx[i]), WALK_BLUR_EXPOSURE)
            Image.fromarray(rgb).save(d / rel[i], quality=95)
        write_transforms(d / js, cams, rel)
    print(f"rendered {scene}: {len(walk)} walk frames, {len(off)} off-path test views -> {d}")
    return d / "transforms.json"


def offpath_views(scene: str, out: Path, data: Path | None):
    """(cameras, image paths) of the scene's test views off the capture path, or None (real scenes)."""
    if scene != "room" and walk_spec(scene) is None:
        return None
    from curate.core.transforms_json import read_transforms
    return read_transforms(synthetic_root(out, data) / scene / "offpath.json")


def holdout_blocks(n: int, blocks: int, length: int, gap: int, fold: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(pool, held_out) indices of ``n`` frames in capture order: ``blocks`` contiguous blocks of
    ``length`` frames held out, one in each of ``blocks`` equal stretches of the capture, and
    ``gap`` frames on each side of a block in neither (not trained on, not scored). Fold o
    shifts every block by o * length frames within its stretch (fold 0: ``gap`` frames after
    the stretch's start), so the folds hold out different frames; a fold that does not fit in
    the stretch is refused."""
    if blocks < 1 or length < 1 or gap < 0 or fold < 0:
        raise ValueError(f"hold-out blocks {blocks}:{length}:{gap} fold {fold}: need N >= 1, L >= 1, G >= 0, fold >= 0")
    stretch = n / blocks
    folds = int((stretch - 2 * gap) // length)
    if fold >= folds:
        raise ValueError(f"hold-out blocks {blocks}:{length}:{gap}: {n} frames give {folds} fold(s) "
                         f"(0..{folds - 1}), not fold {fold}")
    hold, drop = [], []
    for k in range(blocks):
        s = int(np.floor(k * stretch)) + gap + fold * length
        hold += range(s, s + length)
        drop += list(range(s - gap, s)) + list(range(s + length, s + length + gap))
    held = np.asarray(hold, int)
    out = np.zeros(n, bool)
    out[held] = True
    out[np.asarray(drop, int)] = True
    return np.flatnonzero(~out), held


def synthetic_root(out: Path, data: Path | None) -> Path:
    """Where the synthetic scenes are rendered: ``data`` when packed, else ``out/scenes`` (not
    ``out/<scene>``: that is the scene's run folder, which must not hold its inputs)."""
    return data if data is not None else out / "scenes"


def scene_poses(scene: str, out: Path, data: Path | None = None) -> Path:
    """A transforms.json for ``scene``: under ``data`` when packed (``--pack``), else written
    under ``out`` with absolute paths to the photos in ``../shared/data``."""
    if scene == "room":
        return room_scene(synthetic_root(out, data))
    if walk_spec(scene) is not None:
        return walk_scene(synthetic_root(out, data), scene)
    if data is not None:
        p = data / scene / "transforms.json"
        if not p.is_file():
            raise SystemExit(f"{p}: missing (pack it with --pack {data})")
        return p
    p = out / f"{scene}_transforms.json"
    if not p.is_file():
        from curate.core.transforms_json import write_transforms
        cams, files = scene_cameras(scene)
        write_transforms(p, cams, files)
    return p


def pack(scenes: list[str], dest: Path, side: int) -> None:
    """Copy every scene's photos, downscaled to ``side`` px (longer side), with a transforms.json
    of relative paths into ``dest/<scene>/``: a small, self-contained copy that travels to
    another machine (a GPU worker) without ``../shared``."""
    from PIL import Image
    from tqdm import tqdm
    from curate.core.transforms_json import write_transforms
    from curate.field.train import load_image
    for scene in scenes:
        if scene == "room" or walk_spec(scene) is not None:   # synthetic: rendered straight into dest
            room_scene(dest) if scene == "room" else walk_scene(dest, scene)
            continue
        cams, files = scene_cameras(scene)
        f = np.minimum(1.0, side / np.maximum(cams.width, cams.height))
        small = cams.scaled_images(f)
        (dest / scene / "images").mkdir(parents=True, exist_ok=True)
        rel = []
        for i, src in enumerate(tqdm(files, desc=f"pack {scene}")):
            r = f"images/{i:04d}_{Path(src).stem}.jpg"
            img = load_image(src, int(small.width[i]), int(small.height[i]))
            Image.fromarray(np.clip(img * 255 + 0.5, 0, 255).astype(np.uint8)).save(dest / scene / r, quality=95)
            rel.append(r)
        write_transforms(dest / scene / "transforms.json", small, rel)
        print(f"packed {scene}: {len(rel)} images at <= {side} px -> {dest / scene}")


def prepare(scene: str, out: Path, ev, train: bool = True, data: Path | None = None) -> Path:
    """Run folder with imported poses and (``train``) the occupancy stage done with a field trained
    on fold 0's pool (``refine.field`` 'always'): it refines the occupancy and is fold 0's 'all' ceiling."""
    from dataclasses import replace as _replace
    from curate.config import RunConfig
    from curate.core.stats import holdout_split
    from curate.occupancy.stage import occupancy as stage_occupancy
    from curate.sfm.pose_import import import_poses
    from curate.sfm.io import load_sfm
    run = out / scene
    cfg = RunConfig(evaluate=ev)
    cfg = _replace(cfg, refine=_replace(cfg.refine, field="always"))
    # the harness's protocol (docs/investigations/selection.md) imports the poses alone: no triangulated points
    import_poses(_replace(cfg.sfm, triangulate="off"), scene_poses(scene, out, data), run)
    if train:
        pool = holdout_split(len(load_sfm(run).cameras), ev.holdout_every)[0].tolist()
        stage_occupancy(cfg, run, train_on=pool)
    return run


def node_grid(run: Path, cams):
    """The run's selection nodes; without an occupancy stage (``--proxy-only``), every node
    of a 32^3 grid over the scene box (printed)."""
    from curate.core.grid import NodeGrid
    from curate.core.run import load_node_grid
    from curate.core.stage import read_stage
    from curate.field.train import default_box
    if read_stage(run / "occupancy") is not None:
        return load_node_grid(run)
    print(f"{run.name}: no occupancy stage: nodes = the whole 32^3 grid over the scene box")
    b = default_box(cams)
    return NodeGrid(b[0], b[1], 32)


def _variants():
    from research.coverage import CoverageConfig
    from research.medoids_variants import MedoidsVariantConfig as M
    from research.variants import Variant
    from curate.select.config import MedoidsConfig
    from curate.select.config import SelectConfig
    return {"medoids_p2": Variant("medoids", medoids=M(power=2.0)),
            "medoids_p05": Variant("medoids", medoids=M(power=0.5)),
            "medoids_e25": Variant("medoids", medoids=M(energy_share=0.25)),
            "medoids_sharp": Variant("medoids", medoids=M(sharpness_weight=1.0)),
            "medoids_half": Variant("medoids", medoids=M(stride_share=0.5)),
            "medoids_sinit": Variant("medoids", medoids=M(init="stride")),
            "pathstride": Variant("path_stride"),
            "pathstride_l05": Variant("path_stride", look_scale=0.5),
            "pathstride_g05": Variant("path_stride", arc_power=0.5),
            "medoids_l05": Variant("medoids", medoids=M(look_scale=0.5)),
            "medoids_path": SelectConfig("medoids", medoids=MedoidsConfig(path_weights=True)),
            "medoids_plain": SelectConfig("medoids", medoids=MedoidsConfig(path_weights=False)),
            "medoids_p025": Variant("medoids", medoids=M(power=0.25)),
            "medoids_p025_plain": Variant("medoids", medoids=M(power=0.25, path_weights=False)),
            "fvs_rot1": Variant("fvs", fvs_rot_weight=1.0),
            "cells_T1": Variant("coverage", coverage=CoverageConfig(objective="cells", cell_views=1)),
            "cov_pose": Variant("coverage", coverage=CoverageConfig(similarity="pose")),
            "cov_cells": Variant("coverage", coverage=CoverageConfig(similarity="cells"))}


def oracle_subset(view_dist_hold: np.ndarray, budget: int) -> list[int]:
    """NOT a selection method: it sees the held-out views. Round robin over the held-out
    views, each takes its nearest pool view (view medoids' distance) not taken yet, until
    ``budget`` are taken: the subset that camera placement alone could best fit to this test
    set, an upper bound on what knowing where the test views are is worth.

    view_dist_hold: [H, K] held-out -> pool distances. Returns pool-relative indices."""
    order = np.argsort(view_dist_hold, axis=1, kind="stable")          # [H, K]
    limit = min(budget, view_dist_hold.shape[1]) if len(order) else 0
    taken: list[int] = []
    seen = np.zeros(view_dist_hold.shape[1], bool)
    nxt = np.zeros(len(order), int)
    while len(taken) < limit:
        for h in range(len(order)):
            while seen[order[h, nxt[h]]]:
                nxt[h] += 1
            k = int(order[h, nxt[h]])
            seen[k] = True
            taken.append(k)
            if len(taken) == limit:
                break
    return taken


# ------------------------------------------------------------------ proxies
def proxies(pc, hc, cell_sim_hold, chosen, view_dist_hold) -> dict:
    """Held-out view -> chosen cameras: nearest centre, smallest angle, best cell overlap,
    nearest view in view medoids' distance (``view``; ``view_per``: per held-out view)."""
    ch = np.asarray(chosen, int)
    d = np.linalg.norm(hc.centres[:, None] - pc.centres[ch][None], axis=2).min(1)
    a = np.degrees(np.arccos(np.clip(hc.view_dirs @ pc.view_dirs[ch].T, -1, 1))).min(1)
    ov = cell_sim_hold[:, ch].max(1)
    v = view_dist_hold[:, ch].min(1)
    r = lambda x: round(float(x), 4)  # noqa: E731
    return {"pos": r(d.mean()), "pos90": r(np.percentile(d, 90)), "ang": r(a.mean()),
            "ang90": r(np.percentile(a, 90)), "cell": r(ov.mean()), "view": r(v.mean()), "view_per": v}


@dataclass
class PairMeasures:
    """Camera-to-camera measures over all of a scene's cameras, from one pair index; every
    hold-out fold slices them (:meth:`fold`)."""
    cells: object                  # scipy CSR [N, N]: share of i's (node, bin) cells that j also observes
    centres: np.ndarray            # [N, 3] view medoids' embedding: camera centres
    looks: np.ndarray              # [N, 3] and look-at points
    sharpness: np.ndarray          # [N] image sharpness (curate.sfm.quality.sharpness) of each camera's photo

    @classmethod
    def build(cls, cams, grid, bins, paths) -> "PairMeasures":
        from research.coverage import cell_similarity
        from curate.select.medoids import embed, view_depths
        from curate.sfm.quality import files_sharpness
        from curate.select.visibility import build_pair_index
        idx = build_pair_index(cams, grid.nodes(), bins)
        c, a = embed(cams, view_depths(cams, grid.nodes(), idx))
        return cls(cell_similarity(idx, 0.0).tocsr(), c, a, files_sharpness(paths))

    def fold(self, pool, hold) -> tuple[np.ndarray, np.ndarray]:
        """From each held-out view to each pool view, both [H, K]: the share of the held-out
        view's (node, bin) cells that the pool view also observes, and view medoids'
        distance (:func:`curate.select.medoids.view_distance`, per-camera depths from the nodes)."""
        from curate.select.medoids import view_distance
        return self.cells[hold][:, pool].toarray(), view_distance(self.centres, self.looks, hold, pool)


def report_part(part: str, on_path: bool, n_hold: int, mask, B: int, n_pool: int, methods, per_view: dict,
                per_run: dict, prox: dict, timing: dict, ev, default_method: str, cand: str,
                rows: list, paired: list, series: dict) -> None:
    """Print and record one table: the views of ``mask`` (on the capture path, or off it).

    ``per_view``: method -> [tests] PSNR averaged over its trainings; ``per_run``: method ->
    [runs][tests]; ``prox``: method -> proxies per subset (on-path views only). Appends to
    ``rows``, ``paired`` and ``series``.
    """
    from curate.core.stats import paired_difference
    pv = {m: v[mask] for m, v in per_view.items()}
    runs = {m: [round(float(x[mask].mean()), 3) for x in v] for m, v in per_run.items()}
    what = f"{n_hold} held out" if on_path else f"{int(mask.sum())} test views off the capture path"
    print(f"\n{part}: {B} of {n_pool} pool images, {what} "
          f"(max_side {ev.max_side}, {ev.iters} it)")
    print(f"{'method':10s} {'PSNR':>7s}  {'runs':28s} {'pos':>6s} {'pos90':>6s} {'ang':>5s} {'ang90':>6s} "
          f"{'cell':>6s} {'view':>6s} {'r_loss':>6s} {'sel s':>6s}")
    for m in methods:
        pr = prox.get(m) if on_path else None
        pm = {k: float(np.mean([p[k] for p in pr])) for k in pr[0] if k != "view_per"} if pr else {}
        if pr and m in pv and "all" in pv and m != "all" and len(pv[m]) > 2:
            # does what this subset loses against all the pool, view by view, follow the
            # distance to its nearest chosen view? (over the distances this subset leaves)
            loss, near = pv["all"] - pv[m], np.mean([p["view_per"] for p in pr], axis=0)
            if loss.std() > 0 and near.std() > 0:
                pm["r_loss_view"] = float(np.corrcoef(loss, near)[0, 1])
        row = {"scene": part, "budget": B, "pool": n_pool, "method": m,
               "method_name": default_method if m == "default" else m,
               "psnr": round(float(pv[m].mean()), 3) if m in pv else None,
               "runs": runs.get(m, []), **{k: round(v, 4) for k, v in pm.items()},
               "select_s": timing.get(m)}
        rows.append(row)
        ps = f"{row['psnr']:7.2f}" if row["psnr"] is not None else "      -"
        px = (f"{pm['pos']:6.3f} {pm['pos90']:6.3f} {pm['ang']:5.1f} {pm['ang90']:6.1f} {pm['cell']:6.3f} "
              f"{pm['view']:6.3f} {pm.get('r_loss_view', float('nan')):6.2f}" if pm else " " * 48)
        print(f"{m:10s} {ps}  {str(runs.get(m, '')):28s} {px} {timing.get(m, 0) or 0:6.2f}")
        if row["psnr"] is not None:
            series.setdefault(part, {}).setdefault(m, []).append((B, row["psnr"]))
    if cand in pv:
        for o in [m for m in ("random", "fvs", "energy", "default", "coverage", "medoids", "stride", "oracle", "all")
                  if m != cand]:
            if o in pv:
                d = paired_difference(pv[cand], pv[o])
                d = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in d.items()}
                paired.append({"scene": part, "budget": B, "pair": f"{cand}-{o}", **d})
                print(f"  {cand} - {o:7s} {d['mean']:+.2f} dB  (95% CI {d['lo']:+.2f} to {d['hi']:+.2f}, "
                      f"{d['n']} views)")
        if all(m in pv for m in ("random", "all")):
            room = pv["all"].mean() - pv["random"].mean()
            if room > 1e-6:
                g = (pv[cand].mean() - pv["random"].mean()) / room
                paired.append({"scene": part, "budget": B, "pair": f"gap_closed_{cand}", "mean": round(float(g), 3)})
                print(f"  gap closed ({cand} - random) / (all - random): {g:.2f}")


@dataclass
class Bench:
    """What every fold of every scene shares: the options, the methods, and the tables the
    harness appends to (``rows``, ``paired``, ``series``)."""
    args: argparse.Namespace
    ev: object                     # curate.evaluate.units.EvalConfig
    methods: list
    default: object                # curate.select.config.SelectConfig
    label: dict                    # method -> its unit folders' name
    rows: list
    paired: list
    series: dict


FOLD_SEED = 1000
"""Random draw s of hold-out fold o > 0 uses seed ``FOLD_SEED * o + s`` (:func:`random_seed`)."""


def random_seed(fold: int, draw: int, shared: bool = False) -> int:
    """Seed of random subset ``draw`` in hold-out fold ``fold``. The folds' pools differ by a
    shift of one image, so one seed in every fold draws nearly the same cameras each time
    (``shared``: how the harness drew them before 2026-11-23); by default each fold > 0
    draws its own (fold 0 keeps seeds 0, 1, ...), so the random mean over folds averages
    independent subsets."""
    return int(draw) if shared or fold == 0 else FOLD_SEED * int(fold) + int(draw)


def unit_label(h: "Bench", method: str, fold: int) -> str:
    """Name of ``method``'s unit folders in ``fold``: random subsets drawn per fold
    (:func:`random_seed`) are ``randomf`` in folds > 0, so they never meet the units that
    ``--shared-seeds`` draws."""
    if method == "random" and fold > 0 and not h.args.shared_seeds:
        return "randomf"
    return h.label.get(method, method)


UNIT_KEY = re.compile(r"q_(?P<label>.+?)(?:_s(?P<draw>\d+))?_b(?P<budget>\d+)_t(?P<seed>\d+)(?:_o(?P<fold>\d+))?$")
"""Parses :func:`unit_key` (scripts that read a harness run's units use it)."""


def unit_key(label: str, budget: int, seed: int, fold: int, draw: int | None = None) -> str:
    """Folder name (under ``RUN/evaluate``) of one training: method label, random ``draw``
    (random subsets only), budget, training seed, hold-out fold (``_o<fold>`` for fold > 0,
    so fold 0 keeps the names of a single hold-out)."""
    return f"q_{label}{'' if draw is None else f'_s{draw}'}_b{budget}_t{seed}{f'_o{fold}' if fold else ''}"


def is_unit(key: str, label: str, budget: int, fold: int) -> bool:
    """``key`` is a unit of ``label`` at ``budget`` in ``fold`` (any draw, any training seed;
    ``medoids`` does not take ``medoids_p2``'s units)."""
    m = UNIT_KEY.match(key)
    return bool(m) and m["label"] == label and int(m["budget"]) == budget and int(m["fold"] or 0) == fold


def train_key(ev, subset: list[int], holdout: list[int], deps: list[str]) -> str:
    """Stage key of one harness training: its settings (an ``EvalConfig`` without the fields
    that do not change a training: workers, methods, random seeds), the subset and held-out
    views (absolute indices) and the keys it depends on. A unit whose stage holds another
    key is retrained (or reported stale)."""
    from curate.core.stage import stage_key
    return stage_key({"train": replace(ev, workers=0, methods=(), random_seeds=0), "subset": subset,
                      "holdout": holdout}, deps)


def default_label(default) -> tuple[str, str]:
    """(auto's rule, tag) of curate's default: the tag names its unit folders
    (``q_default-<tag>_...``). ``auto`` picks its method by kind of capture, a rule that is
    not in :class:`curate.select.config.SelectConfig`, so the rule goes into the tag too: when the
    rule changes, the default trains into new folders instead of meeting the old ones."""
    from curate.select import methods
    from curate.core.stage import stage_key
    rule = f"auto: walk={methods.WALK_METHOD}, object={methods.OBJECT_METHOD}" \
        if default.method == "auto" else ""
    return rule, stage_key(default, [rule] if rule else [])[:6]


def stale_units(run: Path, keys: dict[str, str]) -> list[str]:
    """Unit keys of ``keys`` (unit key -> stage key) whose folder ``run/evaluate/<unit>`` holds a
    finished training with another stage key: a different subset or settings under the same
    name (e.g. a method whose default changed since). Training it would overwrite that result."""
    from curate.core.stage import read_stage
    out = []
    for u, k in keys.items():
        rec = read_stage(run / "evaluate" / u)
        if rec is not None and rec.get("key") not in (None, k):
            out.append(u)
    return out


def run_fold(h: Bench, scene: str, run: Path, sfm, paths, grid, measures: PairMeasures, fold: int,
             out: Path, data: Path | None) -> dict:
    """Select, train and report every budget of one hold-out fold (images ``fold``,
    ``fold + every``, ... held out) of the scene's run folder ``run`` (its ``sfm`` result,
    image ``paths``, selection nodes ``grid`` and camera ``measures`` are the same for every
    fold). Unit folders of fold o > 0 end in ``_o<o>``, so fold 0 keeps the names (and
    finished units) of a single hold-out. Returns budget -> (per_view, per_run, prox,
    n_hold, B, n_pool) of its on-path views and the per_view of its off-path views (None for
    a real scene), for :func:`report_folds`."""
    from curate.core.budget import parse_budget, resolve_budget
    from curate.evaluate.units import Unit, eval_cameras, run_units
    from curate.select.config import SelectConfig
    from curate.select.select import select
    from research.variants import Variant, select_variant
    from curate.core.stage import read_stage
    from curate.core.stats import holdout_split
    from curate.field.train import default_box
    from curate.select.visibility import build_pair_index
    args, ev, methods = h.args, h.ev, h.methods
    blocks = parse_blocks(args.holdout_blocks)
    pool, hold = (holdout_blocks(len(sfm.cameras), *blocks, fold) if blocks
                  else holdout_split(len(sfm.cameras), ev.holdout_every, fold))
    pool, hold = pool.tolist(), hold.tolist()
    suffix, name = (f"_o{fold}", f"{scene}@{fold}") if fold else ("", scene)
    pc, hc = sfm.cameras[pool], sfm.cameras[hold]
    cs_hold, vd_hold = measures.fold(pool, hold)
    tests, all_cams, all_paths = list(hold), sfm.cameras, list(paths)   # evaluated views
    off = offpath_views(scene, out, data)
    if off is not None:                                  # appended after the registered cameras
        from curate.core.cameras import Cameras
        all_cams, all_paths = Cameras.concat([sfm.cameras, off[0]]), all_paths + list(off[1])
        tests += list(range(len(sfm.cameras), len(all_cams)))
    on = np.arange(len(tests)) < len(hold)
    parts = [(name, on)] + ([(f"{name}-offpath", ~on)] if off is not None else [])
    cams = eval_cameras(all_cams, ev.max_side)
    box = default_box(sfm.cameras)
    sfm_key = read_stage(run / "sfm")["key"]
    occ_key = (read_stage(run / "occupancy") or {}).get("key", "")
    found, index = {}, {}                                # index: bins -> the pool's pair index
    for b in [x for x in args.budgets.split(",") if x]:
        B = resolve_budget(parse_budget(b), len(pool))
        subsets: dict[str, list[list[int]]] = {}   # method -> subsets (pool-relative indices)
        timing = {}                                 # method -> selection seconds, pair index excluded
        for m in methods:
            if m == "all":
                continue
            if m == "oracle":
                subsets[m] = [oracle_subset(vd_hold, B)]
                timing[m] = 0.0
                continue
            if m == "random":
                cfgs = [SelectConfig("random", seed=random_seed(fold, s, args.shared_seeds))
                        for s in range(args.random_seeds)]
            else:
                cfgs = [h.default if m == "default" else VARIANTS[m] if m in VARIANTS else SelectConfig(m)]
            subsets[m] = []
            for c in cfgs:
                if c.energy.bins not in index:       # one pair index per fold and bins, not per method
                    index[c.energy.bins] = build_pair_index(pc, grid.nodes(), c.energy.bins, device=c.device)
                if isinstance(c, Variant):
                    s = select_variant(c, pc, grid, B, index=index[c.energy.bins], sharpness=measures.sharpness[pool])
                else:
                    s = select(pc, grid, B, c, index=index[c.energy.bins])
                subsets[m].append(s.chosen)
                timing[m] = round(s.seconds, 3)
        prox = {m: [proxies(pc, hc, cs_hold, ch, vd_hold) for ch in v] for m, v in subsets.items()}
        groups = {}
        for m, subs in ({} if args.proxy_only else subsets).items():
            for si, ch in enumerate(subs):
                seeds = [0] if m in ("random", *args.one_seed.split(",")) else list(range(args.train_seeds))
                for t in seeds:
                    key = unit_key(unit_label(h, m, fold), B, t, fold, si if m == "random" else None)
                    u = Unit(key, m, si if m == "random" else t, [pool[k] for k in ch])
                    groups.setdefault(t, []).append(u)
        if "all" in methods and not args.proxy_only:
            groups.setdefault(0, []).append(Unit(f"all{suffix}", "all", None, list(pool)))
        plan = []                                    # (seed config, units, their stage keys) per training seed
        for t, us in sorted(groups.items()):
            cfg_t = replace(ev, train_seed=t)
            plan.append((cfg_t, us, {u.key: train_key(cfg_t, u.subset, tests,
                                                      [sfm_key] + ([occ_key] if u.key == "all" else []))
                                     for u in us}))
        stale = stale_units(run, {k: v for _, _, keys in plan for k, v in keys.items()})   # before any training
        if stale and not args.overwrite:
            raise SystemExit(f"{run}: {len(stale)} unit(s) already hold another subset or other settings "
                             f"under the same name ({', '.join(stale[:4])}{', ...' if len(stale) > 4 else ''}): "
                             "did a method's default change? Use another --out or a variant name "
                             "(e.g. --extra medoids_plain), or pass --overwrite to retrain them in place.")
        # the occupancy stage's field was trained on fold 0's pool: the 'all' ceiling of fold 0 only
        # (not of a block hold-out: it saw those frames)
        fp = {} if blocks else {"all": str(run / "occupancy" / "field.pt")}
        results: dict[str, dict] = {}
        for cfg_t, us, keys in plan:
            results.update(run_units(run, us, keys, cfg_t, cams, all_paths, tests, box, fp, progress=False))
        # per method: per-view PSNR averaged over its trainings (random: over its seeds)
        per_view, per_run = {}, {}
        for m in methods:
            lab = unit_label(h, m, fold)
            rs = [r for k, r in results.items() if (k == f"all{suffix}" if m == "all" else is_unit(k, lab, B, fold))]
            if not rs:
                continue
            per_view[m] = np.mean([[v["psnr"] for v in r["per_view"]] for r in rs], axis=0)
            per_run[m] = [np.array([v["psnr"] for v in r["per_view"]]) for r in rs]   # [runs][views]
        for part, mask in parts:   # on the capture path (held out); off it (synthetic scenes)
            report_part(part, part == name, len(hold), mask, B, len(pool), methods, per_view, per_run, prox,
                        timing, ev, h.default.method, args.candidate, h.rows, h.paired,
                        {} if fold else h.series)        # plotted: fold 0 and the pooled folds
        found[b] = ({m: v[on] for m, v in per_view.items()}, {m: [x[on] for x in v] for m, v in per_run.items()},
                    prox, len(hold), B, len(pool),
                    {m: v[~on] for m, v in per_view.items()} if off is not None else None)   # off-path views
    return found


def report_folds(h: Bench, scene: str, folds: list) -> None:
    """One table (``<scene>-folds``) over the on-path held-out views of every fold of one
    budget: each method's per-view PSNRs are concatenated over the folds (its run r of every
    fold make its run r), and the paired differences pair views across all folds. A scene
    with test views off the path (every fold scores the same ones) adds
    ``<scene>-offpath-folds``: each view's PSNR averaged over the folds, paired per view."""
    methods = [m for m in h.methods if all(m in f[0] for f in folds)]
    per_view = {m: np.concatenate([f[0][m] for f in folds]) for m in methods}
    n_runs = {m: min(len(f[1][m]) for f in folds) for m in methods}
    per_run = {m: [np.concatenate([f[1][m][r] for f in folds]) for r in range(n_runs[m])] for m in methods}
    prox = {}
    for m in [m for m in methods if all(m in f[2] for f in folds)]:
        n = min(len(f[2][m]) for f in folds)
        prox[m] = [{k: (np.concatenate([f[2][m][i][k] for f in folds]) if k == "view_per"
                        else float(np.mean([f[2][m][i][k] for f in folds]))) for k in folds[0][2][m][0]}
                   for i in range(n)]
    n_hold, B = sum(f[3] for f in folds), folds[0][4]
    n_pool = int(round(np.mean([f[5] for f in folds])))
    print(f"\n{len(folds)} folds pooled (budgets {sorted({f[4] for f in folds})}):", end="")
    report_part(f"{scene}-folds", True, n_hold, np.ones(n_hold, bool), B, n_pool, methods, per_view, per_run,
                prox, {}, h.ev, h.default.method, h.args.candidate, h.rows, h.paired, h.series)
    if all(f[6] is not None for f in folds):
        # off the path every fold scores the same views: each view's PSNR is averaged over the
        # folds (one number per view and method), and the methods are paired over those views
        off = {m: np.mean([f[6][m] for f in folds], axis=0) for m in methods}
        n_off = len(next(iter(off.values())))
        print(f"\n{len(folds)} folds averaged per off-path view:", end="")
        report_part(f"{scene}-offpath-folds", False, n_hold, np.ones(n_off, bool), B, n_pool, methods, off,
                    {m: [v] for m, v in off.items()}, {}, {}, h.ev, h.default.method, h.args.candidate,
                    h.rows, h.paired, {})


def parse_blocks(spec: str) -> tuple[int, int, int] | None:
    """``--holdout-blocks N:L:G`` -> (N, L, G); '' -> None."""
    if not spec:
        return None
    try:
        n, length, gap = (int(x) for x in spec.split(":"))
    except ValueError:
        raise SystemExit(f"--holdout-blocks {spec!r}: expected N:L:G, e.g. 6:4:3") from None
    return n, length, gap


def write_psnr_plot(series: dict, out: Path) -> Path:
    """SVG of held-out PSNR against the budget, one chart per scene (stacked), under ``out``.
    ``series``: scene -> method -> [(budget, PSNR)]. Returns its path."""
    from curate.html.charts import line_chart
    svg = []
    for scene, ser in series.items():
        s = {m: ([x for x, _ in sorted(v)], [y for _, y in sorted(v)]) for m, v in ser.items()}
        svg.append(line_chart(s, f"{scene}: held-out PSNR", "images chosen", "PSNR (dB)"))
    tag = "_".join(series)
    if len(tag) > 100:                      # many scenes: a name the file system takes
        import hashlib
        tag = f"{next(iter(series))}_and_{len(series) - 1}_more_{hashlib.sha1(tag.encode()).hexdigest()[:8]}"
    p = out / f"quality_psnr_{tag}.svg"
    if len(svg) == 1:
        p.write_text(svg[0])
    else:  # stack the charts in one SVG
        body = "".join(f'<g transform="translate(0,{310 * i})">{x}</g>' for i, x in enumerate(svg))
        p.write_text(f'<svg xmlns="http://www.w3.org/2000/svg" width="520" height="{310 * len(svg)}">{body}</svg>')
    return p


# ------------------------------------------------------------------ the harness
def main(argv=None) -> int:
    global SKULL_SFM, VARIANTS
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="office,fox,templering",
                    help="office, fox, templering, skull (real captures), room (a synthetic walk, "
                    "rendered by the harness, with test views off the path too) and walk-<kind>[-<layout>] "
                    "(hand-held walks of curate.simulate.walks, e.g. walk-corridor, walk-turn-kitchen; "
                    "walk-blur, walk-fast; "
                    "-s<seed> at the end: another trajectory of the same kind, e.g. walk-loop-office-s2)")
    ap.add_argument("--budgets", default="10%,17%,30%", help="counts or pool fractions, comma separated")
    ap.add_argument("--train-seeds", type=int, default=2, help="trainings per subset of the selection methods")
    ap.add_argument("--random-seeds", type=int, default=3)
    ap.add_argument("--shared-seeds", action="store_true", help="random draw s uses seed s in every fold, "
                    "as before 2026-11-23 (the figures measured then; folds then repeat nearly the same "
                    "draw); default: each fold > 0 draws its own subsets (unit folders q_randomf_...)")
    ap.add_argument("--one-seed", default="", help="selection methods trained with training seed 0 only (comma list)")
    ap.add_argument("--methods", default="default,energy,fvs,random,all")
    ap.add_argument("--extra", default="", help="more selection methods: METHODS names, or variants "
                    "'fvs_rot1' (FVS with rot_weight 1), 'cells_T1' (coverage objective 'cells', T=1), "
                    "'cov_pose' / 'cov_cells' (coverage with the pose / cells similarity alone), "
                    "'medoids_p2' / 'medoids_p05' / 'medoids_p025' (medoids minimising the mean of the view "
                    "distance ** 2 / ** 0.5 / ** 0.25; 'medoids_p025_plain': without path weights), "
                    "'medoids_e25' (medoids for 75%% of the budget, the paper's greedy energy for the rest), "
                    "'medoids_sharp' (medoids avoiding frames blurrier than their neighbours, sharpness_weight 1), "
                    "'medoids_path' / 'medoids_plain' (medoids with / without path weights; with is the default), "
                    "'oracle' (NOT a method: the held-out views' nearest pool views, an upper bound), "
                    "'stride' (every (pool / budget)-th frame in capture order: a video's usual subsampling)")
    ap.add_argument("--max-side", type=int, default=160)
    ap.add_argument("--iters", type=int, default=600)
    ap.add_argument("--holdout-every", type=int, default=14)
    ap.add_argument("--holdout-offsets", default="0", help="hold-out folds, comma list ('all': 0..every-1): "
                    "fold o holds out images o, o + every, ... and selects from the rest; with more than one, "
                    "a pooled table (<scene>-folds) pairs the methods over every fold's held-out views")
    ap.add_argument("--holdout-blocks", default="", metavar="N:L:G", help="hold out N contiguous blocks of L "
                    "frames (one per N-th of the capture) with G frames each side left out of the pool, "
                    "instead of every n-th frame; --holdout-offsets shift the blocks by L frames; use its own --out")
    ap.add_argument("--candidate", default="default", help="the method compared (paired, per view) with the others")
    ap.add_argument("--workers", type=int, default=1, help="trainings at once (processes; e.g. 4 on one GPU)")
    ap.add_argument("--out", default=str(ROOT / "runs" / "quality"))
    ap.add_argument("--overwrite", action="store_true", help="retrain a unit whose folder holds another "
                    "subset or settings under the same name (default: stop, so no earlier result is lost)")
    ap.add_argument("--proxy-only", action="store_true", help="selections and proxies only (no training)")
    ap.add_argument("--data", default="", help="read scenes packed by --pack from this folder (not ../shared)")
    ap.add_argument("--pack", default="", help="only pack --scenes (photos downscaled to --pack-side, "
                    "relative transforms.json) into this folder for another machine, then stop")
    ap.add_argument("--pack-side", type=int, default=320)
    ap.add_argument("--skull-sfm", default=str(SKULL_SFM), help="run folder of `curate sfm` on skull (its poses)")
    args = ap.parse_args(argv)
    SKULL_SFM = Path(args.skull_sfm)
    scenes = [s for s in args.scenes.split(",") if s]
    if args.pack:
        pack(scenes, Path(args.pack), args.pack_side)
        return 0
    data = Path(args.data).resolve() if args.data else None

    import logging
    logging.basicConfig(level=logging.WARNING)
    from curate.evaluate.units import EvalConfig
    from curate.select.config import SelectConfig

    VARIANTS = _variants()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    ev = EvalConfig(holdout_every=args.holdout_every, max_side=args.max_side, iters=args.iters, workers=args.workers)
    default = SelectConfig()
    auto_rule, default_tag = default_label(default)
    methods = [m for m in args.methods.split(",") if m] + [m for m in args.extra.split(",") if m]
    rows, paired, series = [], [], {}
    settings = {"max_side": ev.max_side, "iters": ev.iters, "holdout_every": ev.holdout_every,
                "holdout_offsets": args.holdout_offsets, "holdout_blocks": args.holdout_blocks,
                "field": "curate.field.model.FieldConfig() defaults", "train_seeds": args.train_seeds,
                "random_seeds": args.random_seeds,
                "random_draws": "shared by the folds" if args.shared_seeds else "per fold",
                "default_method": default.method,
                "auto_rule": auto_rule, "default_config": asdict(default)}
    t_all = time.perf_counter()
    h = Bench(args, ev, methods, default, {"default": f"default-{default_tag}"}, rows, paired, series)
    if args.holdout_offsets == "all" and args.holdout_blocks:
        raise SystemExit("--holdout-blocks: give the folds as a list (--holdout-offsets 0,1,...)")
    parse_blocks(args.holdout_blocks)                    # a malformed spec stops before any work
    offsets = list(range(ev.holdout_every)) if args.holdout_offsets == "all" else \
        [int(x) for x in args.holdout_offsets.split(",") if x]
    from curate.sfm.io import image_paths, load_sfm
    for scene in scenes:
        run = prepare(scene, out, ev, train=not args.proxy_only, data=data)
        sfm = load_sfm(run)
        paths = image_paths(run, list(sfm.cameras.names), sfm.records)
        grid = node_grid(run, sfm.cameras)
        measures = PairMeasures.build(sfm.cameras, grid, default.energy.bins, paths)
        folds = [run_fold(h, scene, run, sfm, paths, grid, measures, fold, out, data) for fold in offsets]
        if len(folds) > 1 and not args.proxy_only:
            for b in folds[0]:
                report_folds(h, scene, [f[b] for f in folds])
    if series:
        print(f"plot: {write_psnr_plot(series, out)}")
    print(json.dumps({"settings": settings, "rows": rows, "paired": paired,
                      "seconds": round(time.perf_counter() - t_all, 1)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
