#!/usr/bin/env python
"""Benchmark SfM's mapping against the pool size: photo folders of 1,000-3,000 frames and a 300-photo object.

    python3 -m research.bench.bench_mapping --walk 1000 2000 3000 --object 300 [--mappers incremental global]
    python3 -m research.bench.bench_mapping --walk --object --hall 1000 3000 --mappers
    python3 -m research.bench.bench_mapping --walk --object --hall-back 1600 --mappers
    python3 -m research.bench.bench_mapping --walk --object --grid 2000 --mappers

Renders (once, cached under ``--work``, resumable frame by frame):

* one long hand-held loop walk through the synthetic living room
  (:func:`curate.simulate.walks.hand_held_walk`, 640x480, 10 frames a second, motion blur, as in
  :mod:`research.bench.bench_capture`) as numbered JPEG photos ``frame_00000.jpg``...; the pool of
  size N is a folder of hard links to its first N frames (photos, not a video: no ``--max-frames``
  cap; ``--matcher auto`` picks sequential matching for numbered photos);
* a walk down a long hall that never comes back (:func:`hall_walk` through :func:`hall_scene`, same
  size, rate and blur as the loop walk), the pool of size N again its first N frames: new ground all
  the way, where the loop walk keeps revisiting one room;
* ``--hall-back N``: a walk of N frames down the hall on one side and back on the other
  (:func:`hall_there_and_back`): each stretch seen twice, from both sides, a shape between the hall's
  open chain and the loop walk's room seen round and round;
* ``--grid N``: a drone's mapping flight of N frames, straight down over a large room's floor in
  strips back and forth (:func:`grid_flight`): a 2-D pattern of overlaps with no loop along the way;
* an object capture (:func:`object_orbit`): ``--object`` photos of 800x533 taken hand-held in three
  rings around the coffee table of the same room, named ``IMG_0001.jpg``... as a phone names them.

For each pool it runs ``curate sfm POOL --out RUN`` in a child process that times each SfM stage
(wall and CPU seconds of the process, all threads: the machine is shared, so CPU seconds are the
steadier figure) and records its peak memory, then maps the same matches again with each mapper of
``--mappers`` (``incremental``, ``global``, ``hierarchical``; each in its own child process on a copy
of the database, as :mod:`research.sfm_mappers` does), with each mapper's seconds, peak memory,
registered fraction and pose errors against the rendered poses (median / max rotation, median
centre error relative to the extent, after a similarity alignment). Every result is cached as
JSON under ``--work/results``: a killed benchmark resumes where it stopped, and the smaller
pools finish first. Prints one JSON line per result and, last, ``{"results": [...]}``.
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
from curate.sfm.matching import copy_database

FPS = 10.0
EXPOSURE_S = 1 / 120
WORK = Path("/tmp/curate_bench_mapping")


# ------------------------------------------------------------------ rendering
def object_orbit(n: int = 300, seed: int = 0, width: int = 800, height: int = 533, fov_deg: float = 65.0,
                 target=(2.5, 2.55, 0.5)):
    """[n] cameras of a hand-held object capture: three rings around ``target`` (the living room's
    coffee table) at 0.95, 1.3 and 1.65 m, 0.95-1.25 m from it, a photo every ~3.6 degrees, each
    aimed at the object with a few centimetres of aim error and a little roll; photos named
    ``IMG_0001.jpg``... Deterministic from (n, seed)."""
    from curate.core.cameras import Cameras, look_at
    rng = np.random.default_rng(seed)
    rings = [(0.95, 1.25), (1.3, 1.1), (1.65, 0.95)]                       # (height, radius)
    per = np.diff(np.linspace(0, n, len(rings) + 1).round().astype(int))
    c, t = [], []
    tgt = np.asarray(target, float)
    for k, ((h, r), m) in enumerate(zip(rings, per)):
        a = np.linspace(0, 2 * np.pi, m, endpoint=False) + 0.4 * k + rng.normal(0, 0.01, m)
        rr = r + rng.normal(0, 0.03, m)
        c.append(np.stack([tgt[0] + rr * np.cos(a), tgt[1] + rr * np.sin(a), h + rng.normal(0, 0.03, m)], 1))
        t.append(tgt + rng.normal(0, 0.04, (m, 3)))
    c, t = np.concatenate(c), np.concatenate(t)
    c2w = look_at(c, t)
    roll = rng.normal(0, 0.03, n)
    cr, sr = np.cos(roll), np.sin(roll)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = cr, -sr, sr, cr, 1.0
    c2w[:, :3, :3] = c2w[:, :3, :3] @ Rz
    fx = width / 2 / np.tan(np.radians(fov_deg) / 2)
    return Cameras(c2w, fx, fx, width / 2, height / 2, width, height,
                   names=tuple(f"IMG_{i + 1:04d}.jpg" for i in range(n)))


HALL_WIDTH, HALL_HEIGHT = 4.0, 2.7
HALL_SPEED = 0.35          # m/s, the walk's pace (as hand_held_walk's)


def hall_scene(n: int, seed: int = 0):
    """A long furnished hall for a walk of ``n`` frames that never comes back (``HALL_WIDTH`` x
    ``HALL_HEIGHT`` m, 4 m longer than the walk): along both long walls, pictures hung every 0.6-1.8 m
    and, every 1.0-2.4 m, shelves with books, cabinets, tables with things on them, plants and pillars,
    each with its own procedural texture (:class:`curate.simulate.synthetic.Scene`); a ceiling light
    every 5 m. Deterministic from (n, seed)."""
    from curate.simulate.synthetic import Scene, _Builder
    b = _Builder(seed * 1000 + 77)
    L, W, H = 4.0 + n * HALL_SPEED / FPS, HALL_WIDTH, HALL_HEIGHT
    b.room(L, W, H)
    r = b.rng
    for wall in (0, 1):                              # pictures along both walls, each its own texture
        x = float(r.uniform(0.0, 0.5))
        while x < L - 0.5:
            w = float(r.uniform(0.5, 1.3))
            y0, y1 = (0.0, 0.02) if wall == 0 else (W - 0.02, W)
            b.box([x, y0, float(r.uniform(0.9, 1.3))], [x + w, y1, float(r.uniform(1.9, 2.4))])
            x += w + float(r.uniform(0.1, 0.5))
    for wall in (0, 1):
        x = float(r.uniform(0.3, 1.0))
        while x < L - 1.8:
            w, d = float(r.uniform(0.8, 1.5)), float(r.uniform(0.35, 0.7))
            y0 = 0.05 if wall == 0 else W - 0.05 - d
            k = int(r.integers(5))
            if k == 0:
                b.shelf(x, y0, w, d, float(r.uniform(1.5, 2.2)), n=3)
            elif k == 1:
                b.box([x, y0, 0], [x + w, y0 + d, float(r.uniform(0.6, 1.6))])            # cabinet
            elif k == 2:
                h = float(r.uniform(0.7, 0.95))
                b.table(x, y0, w, d, h)
                b.sphere([x + 0.3 * w, y0 + d / 2, h + 0.08], 0.08)
                b.cyl([x + 0.7 * w, y0 + d / 2, h], 0.06, float(r.uniform(0.1, 0.3)))
            elif k == 3:
                c = [x + w / 2, y0 + d / 2]
                b.cyl([*c, 0], 0.18, 0.45)                                                 # plant
                b.sphere([*c, 0.85], float(r.uniform(0.3, 0.42)))
            else:
                b.box([x, y0, 0], [x + 0.35, y0 + 0.35 if wall == 0 else y0 + d, H])     # pillar
            x += w + float(r.uniform(0.2, 0.9))
    lights = np.array([[x, W / 2, H - 0.15] for x in np.arange(2.5, L, 5.0)])
    lo, hi = np.zeros(3), np.array([L, W, H])
    free = ([1.0, 1.0, 1.0], [L - 1.0, W - 1.0, 2.2])
    return Scene("hall", (lo, hi), b.solids, lights, (np.asarray(free[0]), np.asarray(free[1])),
                 np.array([L / 2, W / 2, 1.0]))


def hall_walk(n: int, seed: int = 0, width: int = 640, height: int = 480, fov_deg: float = 60.0):
    """(Cameras [n], angular speed [n] radians a frame) of a hand-held walk down :func:`hall_scene`'s hall,
    one frame at ``FPS``: 2 m in, straight along it at ``HALL_SPEED`` with a slow sway, eye height with a
    walking bob, the gaze swinging between the two walls (up to 70 deg either side of ahead, a swing
    every 8 s) with hand shake and roll as :func:`curate.simulate.walks.hand_held_walk`. It covers new
    ground the whole way: no frame sees what a frame 10 m earlier saw. Names ``frame_00000.jpg``..."""
    from curate.core.cameras import Cameras, look_at
    from curate.simulate.walks import smooth_noise
    rng = np.random.default_rng(seed + 5)
    f = np.arange(n, dtype=float)
    x = 2.0 + f * HALL_SPEED / FPS
    y = HALL_WIDTH / 2 + 0.3 * np.sin(2 * np.pi * f / (11 * FPS))
    z = 1.55 + 0.03 * np.sin(f * 2 * np.pi * 1.8 / FPS)
    c = np.stack([x, y, z], 1)
    shake = 0.004 * np.sqrt(30 / FPS)
    yaw = 1.22 * np.sin(2 * np.pi * f / (8 * FPS)) + smooth_noise(rng, n, 0.1, 3 * int(FPS))
    yaw = yaw + smooth_noise(rng, n, shake, 2)
    pitch = -0.12 + 0.1 * np.sin(2 * np.pi * f / (9 * FPS)) + smooth_noise(rng, n, shake, 2)
    roll = smooth_noise(rng, n, 0.03, int(FPS))
    d = np.stack([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)], 1)
    c2w = look_at(c, c + d)
    cr, sr = np.cos(roll), np.sin(roll)
    Rz = np.zeros((n, 3, 3))
    Rz[:, 0, 0], Rz[:, 0, 1], Rz[:, 1, 0], Rz[:, 1, 1], Rz[:, 2, 2] = cr, -sr, sr, cr, 1.0
    c2w[:, :3, :3] = c2w[:, :3, :3] @ Rz
    fx = width / 2 / np.tan(np.radians(fov_deg) / 2)
    omega = np.abs(np.gradient(yaw)) + np.abs(np.gradient(pitch))
    return Cameras(c2w, fx, fx, width / 2, height / 2, width, height,
                   names=tuple(f"frame_{i:05d}.jpg" for i in range(n))), omega


def hall_there_and_back(n: int, seed: int = 0, width: int = 640, height: int = 480, fov_deg: float = 60.0):
    """(Cameras [n], angular speed [n]) of a walk down :func:`hall_scene`'s hall and back: the first
    ``n - n // 2`` frames as :func:`hall_walk`, 0.5 m right of the hall's middle, then a second such walk
    turned round (half a turn about the vertical through the middle of the stretch walked), 0.5 m to the
    other side, ending where the first began. Every stretch is seen on the way there and again on the way
    back, from the other side: a chain of photos tied to a second chain all along, neither the hall's
    open chain nor the loop walk's room seen round and round (docs/sfm.md, part 5's solver choice).
    The hall: ``hall_scene(n - n // 2)``. Names ``frame_00000.jpg``..."""
    from curate.core.cameras import Cameras
    m = n - n // 2
    there, w_there = hall_walk(m, seed, width, height, fov_deg)
    back, w_back = hall_walk(n - m, seed + 1, width, height, fov_deg)
    c2w_there, c2w_back = there.c2w.copy(), back.c2w.copy()
    c2w_there[:, 1, 3] -= 0.5
    c2w_back[:, 1, 3] -= 0.5
    x0 = 4.0 + (m - 1) * HALL_SPEED / FPS        # x -> x0 - x, y -> W - y: the first frame back at the far end
    turn = np.diag([-1.0, -1.0, 1.0])
    c2w_back[:, :3, :3] = turn @ c2w_back[:, :3, :3]
    c2w_back[:, :3, 3] = c2w_back[:, :3, 3] @ turn.T + [x0, HALL_WIDTH, 0.0]
    c2w = np.concatenate([c2w_there, c2w_back])
    return Cameras(c2w, there.fx[0], there.fy[0], width / 2, height / 2, width, height,
                   names=tuple(f"frame_{i:05d}.jpg" for i in range(n))), np.concatenate([w_there, w_back])


GRID_SPEED = 1.0           # m/s: the drone's ground speed (0.1 m a frame at FPS)
GRID_SPACING = 1.2         # m between strips: 65% side overlap at GRID_ALTITUDE
GRID_ALTITUDE = 3.0        # m above the floor
GRID_MARGIN = 2.5          # m of floor beyond the flight on every side


def grid_plan(n: int) -> tuple[int, float]:
    """(strips, strip length m) of a square grid flight of ``n`` frames: strips along x, ``GRID_SPACING``
    apart, joined by short legs along y; about as many strips as the strip is long over the spacing."""
    path = n * GRID_SPEED / FPS
    k = max(2, int(round(np.sqrt(path / GRID_SPACING))))
    return k, (path - (k - 1) * GRID_SPACING) / k


def grid_scene(n: int, seed: int = 0):
    """A large room under :func:`grid_flight`'s flight of ``n`` frames (``GRID_MARGIN`` m of floor beyond it,
    4.2 m high): the floor tiled with rugs of 0.6-2 m, each its own procedural texture, and every ~2 m2 a
    thing on it (a crate, a drum, a ball, a low table with something on it, a stack of two boxes), none
    taller than 1.3 m; a ceiling light every 4 m. Deterministic from (n, seed)."""
    from curate.simulate.synthetic import Scene, _Builder
    b = _Builder(seed * 1000 + 91)
    k, ls = grid_plan(n)
    L, W, H = ls + 2 * GRID_MARGIN, (k - 1) * GRID_SPACING + 2 * GRID_MARGIN, 4.2
    b.room(L, W, H)
    r = b.rng
    y = 0.0
    while y < W:                                     # rugs: rows of rectangles of their own texture
        d = float(r.uniform(0.6, 2.0))
        x = float(r.uniform(-0.5, 0.0))
        while x < L:
            w = float(r.uniform(0.6, 2.0))
            b.box([max(x, 0.0), y, 0.0], [min(x + w, L), min(y + d, W), float(r.uniform(0.005, 0.02))])
            x += w + float(r.uniform(0.0, 0.3))
        y += d + float(r.uniform(0.0, 0.3))
    for _ in range(int(L * W / 2)):
        cx, cy = float(r.uniform(0.3, L - 0.3)), float(r.uniform(0.3, W - 0.3))
        kind = int(r.integers(5))
        if kind == 0:
            sx, sy = float(r.uniform(0.2, 0.8)), float(r.uniform(0.2, 0.8))
            b.box([cx, cy, 0], [cx + sx, cy + sy, float(r.uniform(0.1, 1.2))])              # crate
        elif kind == 1:
            b.cyl([cx, cy, 0], float(r.uniform(0.1, 0.35)), float(r.uniform(0.2, 1.1)))      # drum
        elif kind == 2:
            rad = float(r.uniform(0.1, 0.35))
            b.sphere([cx, cy, rad], rad)                                                     # ball
        elif kind == 3:
            w, d, h = float(r.uniform(0.6, 1.2)), float(r.uniform(0.4, 0.8)), float(r.uniform(0.4, 0.8))
            b.table(cx, cy, w, d, h)
            b.box([cx + 0.1, cy + 0.1, h], [cx + 0.1 + w / 3, cy + 0.1 + d / 3, h + float(r.uniform(0.05, 0.3))])
        else:
            s1, s2 = float(r.uniform(0.4, 0.9)), float(r.uniform(0.2, 0.5))
            h1 = float(r.uniform(0.2, 0.6))
            b.box([cx, cy, 0], [cx + s1, cy + s1, h1])                                       # two boxes stacked
            b.box([cx + 0.05, cy + 0.05, h1], [cx + 0.05 + s2, cy + 0.05 + s2, h1 + float(r.uniform(0.1, 0.5))])
    lights = np.array([[x, y, H - 0.15] for x in np.arange(2.0, L, 4.0) for y in np.arange(2.0, W, 4.0)])
    lo, hi = np.zeros(3), np.array([L, W, H])
    free = ([1.0, 1.0, 1.5], [L - 1.0, W - 1.0, H - 0.5])
    return Scene("grid", (lo, hi), b.solids, lights, (np.asarray(free[0]), np.asarray(free[1])),
                 np.array([L / 2, W / 2, 0.5]))


def grid_flight(n: int, seed: int = 0, width: int = 640, height: int = 480, fov_deg: float = 60.0):
    """(Cameras [n], angular speed [n] radians a frame) of a drone's mapping flight over :func:`grid_scene`'s
    floor, one frame at ``FPS``: back and forth along x in :func:`grid_plan`'s strips, ``GRID_SPACING`` apart
    (a short leg along y between them), at ``GRID_SPEED`` and ``GRID_ALTITUDE``, the camera straight down with
    the image's top towards +x throughout (a mapping mission's fixed heading), a few degrees of gimbal
    wobble and a few centimetres of height wobble. Each photo overlaps its neighbours along the strip
    (2.6 m footprint along it, 0.1 m a frame) and the strips beside it (3.5 m across, 65% side overlap):
    a 2-D pattern of overlaps with no loop along the way, the shape part 5's solver choice is to be tested
    on (docs/sfm.md). Names ``frame_00000.jpg``..."""
    from curate.core.cameras import Cameras
    from curate.simulate.walks import smooth_noise
    rng = np.random.default_rng(seed + 11)
    k, ls = grid_plan(n)
    step = GRID_SPEED / FPS
    s = np.arange(n) * step
    leg = ls + GRID_SPACING                          # a strip and the leg after it
    j = np.minimum((s // leg).astype(int), k - 1)
    t = s - j * leg
    along = np.minimum(t, ls)
    x = GRID_MARGIN + np.where(j % 2 == 0, along, ls - along)
    y = GRID_MARGIN + j * GRID_SPACING + np.clip(t - ls, 0, GRID_SPACING)
    z = GRID_ALTITUDE + smooth_noise(rng, n, 0.03, int(FPS))
    c = np.stack([x, y, z], 1)
    R0 = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])   # columns: image x, y, optical axis
    ang = np.stack([smooth_noise(rng, n, np.radians(2.0), int(FPS)) for _ in range(3)], 1)
    from scipy.spatial.transform import Rotation
    R = R0[None] @ Rotation.from_rotvec(ang).as_matrix()
    c2w = np.tile(np.eye(4), (n, 1, 1))
    c2w[:, :3, :3], c2w[:, :3, 3] = R, c
    fx = width / 2 / np.tan(np.radians(fov_deg) / 2)
    omega = np.r_[0.0, np.linalg.norm(np.diff(ang, axis=0), axis=1)]
    return Cameras(c2w, fx, fx, width / 2, height / 2, width, height,
                   names=tuple(f"frame_{i:05d}.jpg" for i in range(n))), omega


SCENES = {"walk": "livingroom", "object": "livingroom", "hall": "gallery", "hall_back": "gallery", "grid": "floor"}


def capture_cameras(kind: str, n: int, seed: int = 0):
    """(Cameras [n], angular speed [n] radians a frame or None) of capture ``kind`` ('walk', 'hall' or 'object')."""
    if kind == "walk":
        from curate.simulate.synthetic import make_scene
        from curate.simulate.walks import hand_held_walk
        cams, omega = hand_held_walk(n, "loop", seed=seed, room=make_scene("livingroom", seed).interior, fps=FPS)
        from curate.core.cameras import Cameras
        return Cameras(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height,
                       names=tuple(f"frame_{i:05d}.jpg" for i in range(n))), omega
    if kind == "hall":
        return hall_walk(n, seed)
    if kind == "hall_back":
        return hall_there_and_back(n, seed)
    if kind == "grid":
        return grid_flight(n, seed)
    return object_orbit(n, seed), None


_SCENE: dict = {}


def capture_scene(kind: str, n: int, seed: int = 0):
    """The scene of capture (kind, n, seed), built once per process."""
    key = (kind, n, seed)
    if key not in _SCENE:
        from curate.simulate.synthetic import make_scene
        _SCENE[key] = hall_scene(n, seed) if kind == "hall" else hall_scene(n - n // 2, seed) \
            if kind == "hall_back" else grid_scene(n, seed) if kind == "grid" else make_scene("livingroom", seed)
        _SCENE[key]._raycaster()                     # built once, shared by _lit_near's copies
    return _SCENE[key]


def _lit_near(scene, centre, k: int = 3):
    """``scene`` lit by its ``k`` lights nearest ``centre`` (a hall's far lights add nothing visible and
    each costs a shadow cast per pixel); the ray-casting structure is shared."""
    import dataclasses
    if len(scene.lights) <= k:
        return scene
    near = np.argsort(np.linalg.norm(scene.lights - centre, axis=1))[:k]
    return dataclasses.replace(scene, lights=scene.lights[np.sort(near)])


def _render_chunk(args):
    """Render cameras ``idx`` of capture (kind, n, seed) into ``folder`` as JPEGs (in a worker process)."""
    kind, n, seed, folder, idx = args
    from PIL import Image

    from curate.simulate.walks import motion_blur
    scene = capture_scene(kind, n, seed)
    cams, omega = capture_cameras(kind, n, seed)
    for i in idx:
        rgb, _ = _lit_near(scene, cams.centres[int(i)]).render(cams[int(i)])
        img = rgb[0] if omega is None else motion_blur(rgb[0], omega[i], float(cams.fx[i]), FPS * EXPOSURE_S)
        dst = Path(folder) / cams.names[i]
        Image.fromarray(img).save(str(dst) + ".part.jpg", quality=92)
        os.replace(str(dst) + ".part.jpg", dst)
    return len(idx)


def render(work: Path, kind: str, n: int, upto: int, seed: int = 0, jobs: int = 2) -> Path:
    """Folder of the capture ``kind`` of ``n`` frames with (at least) its first ``upto`` frames rendered;
    frames already there are kept, so a killed rendering resumes. ``truth.npy``: [n, 4, 4] c2w."""
    from multiprocessing import Pool
    folder = work / "frames" / f"{kind}_{SCENES[kind]}_s{seed}_n{n}"
    folder.mkdir(parents=True, exist_ok=True)
    cams, _ = capture_cameras(kind, n, seed)
    np.save(folder / "truth.npy", cams.c2w)
    todo = [i for i in range(min(upto, n)) if not (folder / cams.names[i]).is_file()]
    if not todo:
        return folder
    chunks = [(kind, n, seed, str(folder), todo[a:a + 10]) for a in range(0, len(todo), 10)]
    t, done = time.perf_counter(), 0
    with Pool(jobs) as pool:
        for k in pool.imap(_render_chunk, chunks):
            done += k
            print(f"{folder.name}: rendered {done}/{len(todo)} ({time.perf_counter() - t:.0f} s)", file=sys.stderr,
                  flush=True)
    return folder


def pool_folder(work: Path, frames: Path, n: int) -> Path:
    """A folder of hard links to the first ``n`` photos of ``frames`` (the pool of size n)."""
    names = sorted(p.name for p in frames.glob("*.jpg") if not p.name.endswith(".part.jpg"))[:n]
    if len(names) < n:
        raise RuntimeError(f"{frames}: {len(names)} frames rendered, {n} needed")
    dst = work / "pools" / f"{frames.name}_first{n}"
    dst.mkdir(parents=True, exist_ok=True)
    for nm in names:
        if not (dst / nm).exists():
            os.link(frames / nm, dst / nm)
    return dst


def truth_cameras(frames: Path, kind: str):
    """Ground-truth Cameras of a rendered capture folder (names as the photos)."""
    c2w = np.load(frames / "truth.npy")
    cams, _ = capture_cameras(kind, len(c2w), int(frames.name.split("_s")[1].split("_")[0]))
    assert np.allclose(cams.c2w, c2w)
    return cams


# ------------------------------------------------------------------ child processes
def _timed(cmd: list[str], log: Path) -> dict:
    """Run ``cmd`` (nice as the parent), its stderr to ``log``; its seconds, exit code and peak resident memory
    (MB, of the process; COLMAP runs in it)."""
    t = time.perf_counter()
    with open(log, "w") as err:
        p = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err)
        _, status, ru = os.wait4(p.pid, 0)
    rc = os.waitstatus_to_exitcode(status)
    tail = log.read_text(errors="replace").strip().splitlines()[-3:]
    return {"wall_s": round(time.perf_counter() - t, 1), "rc": rc, "peak_rss_mb": round(ru.ru_maxrss / 1024, 1),
            "cpu_s": round(ru.ru_utime + ru.ru_stime, 1), **({"stderr_tail": tail} if rc else {})}


def _clock() -> tuple[float, float]:
    return time.perf_counter(), time.process_time()


def _since(t0: tuple[float, float]) -> dict:
    w, c = _clock()
    return {"wall_s": round(w - t0[0], 2), "cpu_s": round(c - t0[1], 2)}


def sfm_child(photos: str, run: str, out_json: str, extra: list[str]) -> int:
    """``curate sfm PHOTOS --out RUN EXTRA...`` in this process, each SfM step timed (wall and CPU seconds of
    the process, all its threads) by wrapping curate.sfm's steps where they are called (the SfM run in
    curate.sfm.colmap, the two mappers in curate.sfm.reconstruction); the times go to ``out_json``."""
    import curate.sfm.colmap as C
    import curate.sfm.reconstruction as R
    from curate.cli import main
    steps: dict = {}

    def wrap(name, fn):
        def f(*a, **k):
            t0 = _clock()
            try:
                return fn(*a, **k)
            finally:
                steps.setdefault(name, []).append(_since(t0))
        return f

    for name, mod, attr in (("ingest", C, "prepare_photos"), ("extract", C, "extract"), ("match", C, "match"),
                            ("map", C, "map_capture"), ("map_incremental", R, "map_incremental"),
                            ("map_global", R, "map_global")):
        setattr(mod, attr, wrap(name, getattr(mod, attr)))
    t0 = _clock()
    rc = main(["sfm", photos, "--out", run, *extra])
    Path(out_json).write_text(json.dumps({"rc": rc, "total": _since(t0), "steps": steps}))
    return int(rc or 0)


def map_hierarchical(cfg, db: Path, images: Path, out: Path, cluster: int = 500):
    """{id: Reconstruction} of COLMAP's hierarchical mapper (overlapping clusters of <= ``cluster`` images,
    each mapped incrementally, then merged), with curate's incremental options (seed, initial pair).
    Measured and not adopted (docs/sfm.md): its clusters split on office.mp4 and on the rendered walk."""
    import pycolmap
    o = pycolmap.HierarchicalPipelineOptions()
    o.num_threads = cfg.num_threads
    o.clustering_options.leaf_max_num_images = cluster
    io = o.incremental_options
    io.num_threads, io.random_seed, io.min_num_matches = cfg.num_threads, cfg.seed, cfg.min_num_matches
    io.mapper.random_seed, io.triangulation.random_seed = cfg.seed, cfg.seed
    io.mapper.init_min_num_inliers = cfg.init_min_num_inliers
    io.mapper.abs_pose_min_num_inliers = cfg.register_min_inliers
    io.ba_refine_principal_point = False
    out.mkdir(parents=True, exist_ok=True)
    return pycolmap.hierarchical_mapping(db, images, out, options=o)


def map_child(run: str, kind: str, out_json: str, truth: str, capture: str) -> int:
    """Map the matches of ``RUN/sfm/database.db`` (a copy) again with ``kind`` ('incremental', 'global',
    'hierarchical', 'auto': curate's map_capture); sizes, seconds and pose errors go to ``out_json``."""
    import tempfile

    import pycolmap

    import curate.sfm.reconstruction as C
    from curate.sfm.config import SfmConfig
    from curate.sfm.native import colmap_log
    sfm = Path(run) / "sfm"
    n_kept = json.loads((sfm / "stage.json").read_text())["stats"]["n_kept"]
    cfg = SfmConfig(progress=False)
    rec: dict = {"mapper": kind, "n_kept": n_kept}
    with tempfile.TemporaryDirectory(dir=str(Path(run).parent)) as tmp:
        db = Path(tmp) / "database.db"
        copy_database(sfm / "database.db", db)
        pycolmap.set_random_seed(cfg.seed)
        t0 = _clock()
        with colmap_log(Path(tmp) / "colmap.log"):
            if kind == "incremental":
                models = C.map_incremental(cfg, db, sfm / "images", Path(tmp) / "m", n_kept, False)
            elif kind == "global":
                models = C.map_global(cfg, db, sfm / "images", Path(tmp) / "m")
            elif kind == "hierarchical":
                models = map_hierarchical(cfg, db, sfm / "images", Path(tmp) / "m")
            elif kind == "incremental:colmap_ba":   # COLMAP's global adjustment schedule at every pool size
                colmap_ba = SfmConfig(progress=False, global_ba_above=10**9, global_ba_above_observations=10**12)
                models = C.map_incremental(colmap_ba, db, sfm / "images",
                                           Path(tmp) / "m", n_kept, False)
            elif kind == "auto":
                stats: dict = {}
                models = C.map_capture(cfg, db, sfm / "images", Path(tmp) / "m", n_kept, stats)
                rec["auto"] = stats
            else:
                raise ValueError(kind)
        rec["map"] = _since(t0)
        rec.update(model_record(models, n_kept, truth, capture))
    Path(out_json).write_text(json.dumps(rec))
    return 0


def model_record(models: dict, n_kept: int, truth: str, capture: str) -> dict:
    """Sizes, registered fraction, points and pose errors (against the rendered poses) of a mapper's models."""
    from curate.sfm.model import cameras_from_reconstruction
    sizes = sorted((int(r.num_reg_images()) for r in models.values()), reverse=True)
    rec: dict = {"model_sizes": sizes, "registered_fraction": round(sizes[0] / n_kept, 4) if sizes else 0.0}
    if not sizes:
        return rec
    best = max(models.values(), key=lambda r: r.num_reg_images())
    rec["n_points3D"] = int(best.num_points3D())
    rec["mean_reprojection_error_px"] = round(float(best.compute_mean_reprojection_error()), 3)
    cams = cameras_from_reconstruction(best, warn=False)[0]
    rec.update(pose_record(cams, truth_cameras(Path(truth), capture)))
    return rec


def pose_record(cams, truth, digits: int = 3) -> dict:
    """``cams`` against ``truth`` after one similarity: matched, rotation median / max (deg, to ``digits``), frames
    over 5 deg, centre error median / max relative to the extent."""
    from research.align import pose_errors
    e = pose_errors(cams, truth)
    rd = np.asarray(e["rotation_deg"])
    return {"n_matched": e["n_matched"], "rotation_deg_median": round(e["rotation_deg_median"], digits),
            "rotation_deg_max": round(e["rotation_deg_max"], digits), "n_over_5deg": int((rd > 5).sum()),
            "centre_rel_median": round(e["centre_rel_median"], 5), "centre_rel_max": round(e["centre_rel_max"], 5)}


# ------------------------------------------------------------------ the benchmark
def run_sfm(work: Path, name: str, photos: Path, frames: Path, capture: str, extra: list[str], force: bool) -> dict:
    """``curate sfm`` of one pool (cached): stage times (wall, CPU), peak memory, kept / registered, pose errors."""
    res = work / "results" / f"{name}.sfm.json"
    if res.is_file() and not force:
        return json.loads(res.read_text())
    run = work / "runs" / name
    if run.exists():
        import shutil
        shutil.rmtree(run)
    steps = work / "results" / f"{name}.steps.json"
    proc = _timed([sys.executable, "-m", "research.bench.bench_mapping", "--sfm-child", str(photos), str(run),
                   str(steps), *extra], work / "results" / f"{name}.sfm.log")
    rec: dict = {"name": name, "what": "sfm", "photos": str(photos), "options": extra, "process": proc}
    if proc["rc"] == 0:
        from curate.sfm.io import load_sfm
        st = json.loads((run / "sfm" / "stage.json").read_text())
        s = st["stats"]
        rec.update({"n_photos": len(list(photos.glob("*.jpg"))), "n_kept": s["n_kept"], "matcher": s["matcher"],
                    "mapper": s.get("mapper"), "mappers_tried": s.get("mappers_tried"),
                    "n_registered": s.get("n_registered"), "registered_fraction": s.get("registered_fraction"),
                    "model_sizes": s.get("model_sizes"), "n_pairs_verified": s.get("n_pairs_verified"),
                    "n_points3D": s.get("n_points"), "stage_timings": st.get("timings"),
                    "stage_seconds": st.get("seconds"), "steps": json.loads(steps.read_text())["steps"]})
        rec.update(pose_record(load_sfm(run).cameras, truth_cameras(frames, capture)))
    res.write_text(json.dumps(rec, indent=1))
    return rec


def run_map(work: Path, name: str, kind: str, frames: Path, capture: str, force: bool, tag: str = "") -> dict:
    """One mapper on the matches of ``name``'s SfM run (cached)."""
    res = work / "results" / f"{name}.map_{kind}{tag}.json"
    if res.is_file() and not force:
        return json.loads(res.read_text())
    tmp = work / "results" / f"{name}.map_{kind}{tag}.child.json"
    proc = _timed([sys.executable, "-m", "research.bench.bench_mapping", "--map-child", str(work / "runs" / name),
                   kind, str(tmp), str(frames), capture], work / "results" / f"{name}.map_{kind}{tag}.log")
    rec = {"name": name, "what": f"map_{kind}{tag}", "process": proc}
    if proc["rc"] == 0:
        rec.update(json.loads(tmp.read_text()))
    res.write_text(json.dumps(rec, indent=1))
    return rec


def fit_exponent(n, t) -> float | None:
    """Least-squares slope of log(t) against log(n): t ~ n^k (None under two sizes)."""
    n, t = np.asarray(n, float), np.asarray(t, float)
    if len(n) < 2 or np.any(t <= 0):
        return None
    return round(float(np.polyfit(np.log(n), np.log(t), 1)[0]), 3)


def summarize(work: Path, tag: str = "") -> dict:
    """Per pool: SfM's steps (CPU and wall seconds), peak memory, the mappers' times and errors, and the
    growth exponents of SfM before (the incremental mapper) and after (curate's --mapper auto, mapped again
    on the same matches) over the walk's pool sizes."""
    res = work / "results"
    rows = []
    for f in sorted(res.glob("*.sfm.json")):
        r = json.loads(f.read_text())
        if r["process"]["rc"]:
            rows.append({"name": r["name"], "error": r["process"].get("stderr_tail")})
            continue
        steps = {k: {"cpu_s": round(sum(x["cpu_s"] for x in v), 1), "wall_s": round(sum(x["wall_s"] for x in v), 1)}
                 for k, v in r["steps"].items()}
        row = {"name": r["name"], "n_photos": r["n_photos"], "n_kept": r["n_kept"], "matcher": r["matcher"],
               "sfm_peak_rss_mb": r["process"]["peak_rss_mb"], "sfm_process_cpu_s": r["process"]["cpu_s"],
               "sfm_process_wall_s": r["process"]["wall_s"], "steps": steps,
               "incremental": {k: r.get(k) for k in ("model_sizes", "registered_fraction", "rotation_deg_median",
                                                      "rotation_deg_max", "n_over_5deg", "centre_rel_median",
                                                      "n_points3D")}}
        row["incremental"].update(steps["map"])
        pre = sum(steps[k]["cpu_s"] for k in ("ingest", "extract", "match") if k in steps)
        row["before_cpu_s"] = round(pre + steps["map"]["cpu_s"], 1)
        row["map_share_before"] = round(steps["map"]["cpu_s"] / row["before_cpu_s"], 3)
        for g in sorted(res.glob(f"{r['name']}.map_*.json")):
            if g.name.endswith(".child.json"):
                continue
            m = json.loads(g.read_text())
            key = m["what"].removeprefix("map_")
            if m["process"]["rc"]:
                row[key] = {"error": m["process"].get("stderr_tail")}
                continue
            row[key] = {**m["map"], "peak_rss_mb": m["process"]["peak_rss_mb"],
                        **{k: m.get(k) for k in ("model_sizes", "registered_fraction", "rotation_deg_median",
                                                 "rotation_deg_max", "n_over_5deg", "centre_rel_median",
                                                 "n_points3D", "auto")}}
        after = row.get("auto" + tag)
        if after and "cpu_s" in after:
            row["after_cpu_s"] = round(pre + after["cpu_s"], 1)
            row["map_share_after"] = round(after["cpu_s"] / row["after_cpu_s"], 3)
        rows.append(row)
    out = {"rows": rows}
    for capture, key in (("walk", "growth_exponents"), ("hall", "hall_growth_exponents")):
        walks = sorted((r for r in rows if r["name"].removeprefix(capture + "_").isdigit() and "error" not in r),
                       key=lambda r: r["n_kept"])
        n = [r["n_kept"] for r in walks]
        fits = {"sizes": n, "sfm_before_cpu": fit_exponent(n, [r["before_cpu_s"] for r in walks])}
        for k in ("ingest", "extract", "match", "map"):
            fits[f"{k}_cpu"] = fit_exponent(n, [r["steps"].get(k, {}).get("cpu_s", 0) for r in walks])
        for k in ("global", "hierarchical", "auto" + tag):
            have = [r for r in walks if k in r and "cpu_s" in r[k]]
            if have and len(have) == len(walks):
                fits[f"map_{k}_cpu"] = fit_exponent(n, [r[k]["cpu_s"] for r in have])
        if walks and all("after_cpu_s" in r for r in walks):
            fits["sfm_after_cpu"] = fit_exponent(n, [r["after_cpu_s"] for r in walks])
        out[key] = fits
    return out


def main(argv=None) -> int:
    if argv is None:
        argv = sys.argv[1:]
    if argv[:1] == ["--sfm-child"]:
        return sfm_child(argv[1], argv[2], argv[3], argv[4:])
    if argv[:1] == ["--map-child"]:
        return map_child(*argv[1:6])
    if argv[:1] == ["--summary"]:   # --summary [WORK [TAG]]: the table of the cached results, as JSON
        print(json.dumps(summarize(Path(argv[1]) if len(argv) > 1 else WORK, argv[2] if len(argv) > 2 else ""),
                         indent=1))
        return 0
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--walk", type=int, nargs="*", default=[1000, 2000, 3000], help="pool sizes of the walk")
    ap.add_argument("--walk-frames", type=int, default=3000, help="frames of the whole walk (pools are its prefixes)")
    ap.add_argument("--hall", type=int, nargs="*", default=[],
                    help="pool sizes of the hall walk (new ground all the way: :func:`hall_walk`)")
    ap.add_argument("--hall-frames", type=int, default=3000, help="frames of the whole hall walk")
    ap.add_argument("--hall-back", type=int, nargs="*", default=[],
                    help="pool sizes of the walk down the hall and back (:func:`hall_there_and_back`; pools are "
                         "whole walks, not prefixes)")
    ap.add_argument("--grid", type=int, nargs="*", default=[],
                    help="pool sizes of the drone's grid flight (:func:`grid_flight`; pools are whole flights)")
    ap.add_argument("--object", type=int, nargs="*", default=[300], help="photos of each object capture")
    ap.add_argument("--mappers", nargs="*", default=["global", "hierarchical"],
                    help="mappers to run again on each pool's matches (the SfM run itself maps with --sfm-mapper)")
    ap.add_argument("--object-mappers", nargs="*", default=["global"], help="--mappers of the object captures")
    ap.add_argument("--sfm-mapper", default="incremental", help="--mapper of the `curate sfm` runs")
    ap.add_argument("--tag", default="", help="suffix of the mapper results' names (to keep a rerun apart)")
    ap.add_argument("--work", type=Path, default=WORK, help="renders, pools, run folders and results")
    ap.add_argument("--jobs", type=int, default=2, help="rendering processes")
    ap.add_argument("--force", action="store_true", help="run again (renders stay cached)")
    a = ap.parse_args(argv)
    (a.work / "results").mkdir(parents=True, exist_ok=True)
    out = []
    todo = [("object", n, n) for n in a.object] + [("walk", a.walk_frames, n) for n in sorted(a.walk)] \
        + [("hall", a.hall_frames, n) for n in sorted(a.hall)] + [("hall_back", n, n) for n in sorted(a.hall_back)] \
        + [("grid", n, n) for n in sorted(a.grid)]
    for capture, total, n in todo:
        frames = render(a.work, capture, total, n, jobs=a.jobs)
        photos = pool_folder(a.work, frames, n)
        name = f"{capture}_{n}"
        r = run_sfm(a.work, name, photos, frames, capture, ["--mapper", a.sfm_mapper], a.force)
        out.append(r)
        print(json.dumps(r), flush=True)
        if r["process"]["rc"]:
            continue
        for kind in (a.object_mappers if capture == "object" else a.mappers):
            m = run_map(a.work, name, kind, frames, capture, a.force, a.tag)
            out.append(m)
            print(json.dumps(m), flush=True)
    print(json.dumps({"results": out}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
