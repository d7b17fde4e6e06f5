"""Read the SfM stage's outputs without pycolmap (see ``curate.sfm.colmap`` for the contract).

Also the parts of the SfM stage that need no pycolmap: COLMAP camera-model parameters
to the project's pinhole + ``k1 k2 p1 p2`` intrinsics, the scene normalisation, and
mapping working-copy cameras back to the original photos.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from curate.core.paths import RunPaths
from curate.core.cameras import Cameras
from curate.core.reads import kept, read_json
from curate.core.run import load_cameras

SFM_DIR = "sfm"


class SfmResult(NamedTuple):
    cameras: Cameras        # registered cameras, OpenCV c2w, COLMAP's world frame, working-copy intrinsics
    points: np.ndarray      # [P, 3] float32 sparse points (P may be 0)
    normalization: dict     # {"centre": [3], "scale": s, ...}: x_canonical = scale * (x - centre)
    records: dict           # content of images.json


def sfm_dir(run_dir: str | Path) -> Path:
    return Path(run_dir) / SFM_DIR


def load_sfm(run_dir: str | Path) -> SfmResult:
    """Cameras, sparse points, normalisation and photo records of a finished SfM/import stage, each file read once
    while it stays the same (:mod:`curate.core.run`: the cameras and points are shared, read-only)."""
    d = sfm_dir(run_dir)
    if not (d / "stage.json").is_file():
        raise FileNotFoundError(f"{d}: SfM has not finished in this run folder (no stage.json); run `curate sfm "
                                f"PHOTOS --out {Path(run_dir)}` or `curate run PHOTOS --out {Path(run_dir)}` first")
    cams = load_cameras(run_dir)
    pts = kept(d / "points.npy", "points", _points) if (d / "points.npy").is_file() else np.zeros((0, 3), np.float32)
    return SfmResult(cams, pts, read_json(d / "normalization.json"), read_json(d / "images.json"))


def _points(path: Path) -> np.ndarray:
    """[P, 3] float32 points of ``points.npy``, read-only (shared by every reader: :func:`curate.core.reads.kept`)."""
    pts = np.load(path).astype(np.float32).reshape(-1, 3)
    pts.flags.writeable = False
    return pts


def load_points_rgb(run_dir: str | Path) -> np.ndarray | None:
    """[P, 3] uint8 colours of the sparse points, or None when the stage has none."""
    p = sfm_dir(run_dir) / "points_rgb.npy"
    return np.load(p) if p.is_file() else None


def intrinsics_from_colmap(model: str, params) -> tuple[float, float, float, float, np.ndarray]:
    """COLMAP camera model + params -> ``(fx, fy, cx, cy, dist [4] = k1 k2 p1 p2)``.

    SIMPLE_PINHOLE ``f cx cy``; PINHOLE ``fx fy cx cy``; SIMPLE_RADIAL ``f cx cy k``;
    RADIAL ``f cx cy k1 k2``; OPENCV ``fx fy cx cy k1 k2 p1 p2``. Other models raise
    ``ValueError`` (the caller decides whether to fall back to a pinhole).
    """
    p = [float(x) for x in params]
    dist = np.zeros(4)
    if model == "SIMPLE_PINHOLE":
        f, cx, cy = p
        return f, f, cx, cy, dist
    if model == "PINHOLE":
        fx, fy, cx, cy = p
        return fx, fy, cx, cy, dist
    if model == "SIMPLE_RADIAL":
        f, cx, cy, k = p
        dist[0] = k
        return f, f, cx, cy, dist
    if model == "RADIAL":
        f, cx, cy, k1, k2 = p
        dist[:2] = k1, k2
        return f, f, cx, cy, dist
    if model == "OPENCV":
        fx, fy, cx, cy, *d = p
        return fx, fy, cx, cy, np.array(d, np.float64)
    raise ValueError(f"camera model {model} is not supported "
                     "(use SIMPLE_PINHOLE, PINHOLE, SIMPLE_RADIAL, RADIAL or OPENCV)")


def colmap_from_intrinsics(fx: float, fy: float, cx: float, cy: float, dist) -> tuple[str, list[float]]:
    """The simplest COLMAP model holding these intrinsics: PINHOLE, or OPENCV when distorted."""
    dist = np.asarray(dist, np.float64)
    if np.any(dist != 0):
        return "OPENCV", [fx, fy, cx, cy, *map(float, dist)]
    return "PINHOLE", [fx, fy, cx, cy]


def normalization(cams: Cameras, points: np.ndarray | None = None, pct: float = 1.0) -> dict:
    """Similarity mapping the scene into the canonical box [-1, 1]^3.

    The scene box is the axis-aligned box spanning the ``pct``..``100 - pct`` percentiles
    of the sparse points (robust to stray points), grown to include every camera centre;
    without points (>= 20 needed) it is the box of the camera centres. ``centre`` is the
    box centre and ``scale = 2 / longest side``, so ``x_canonical = scale * (x - centre)``
    and ``x = x_canonical / scale + centre`` undoes it.
    """
    c = cams.centres
    pts = np.zeros((0, 3)) if points is None else np.asarray(points, np.float64).reshape(-1, 3)
    if len(pts) >= 20:
        lo, hi = np.percentile(pts, pct, axis=0), np.percentile(pts, 100 - pct, axis=0)
        src = "points_percentiles+camera_centres"
    else:
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        src = "camera_centres"
    if len(c):
        lo, hi = np.minimum(lo, c.min(0)), np.maximum(hi, c.max(0))
    if not np.all(np.isfinite(lo)):
        lo, hi = -np.ones(3), np.ones(3)
    centre = (lo + hi) / 2
    side = float(np.max(hi - lo))
    scale = 2.0 / side if side > 0 else 1.0
    return {"centre": centre.tolist(), "scale": scale, "box_min": lo.tolist(), "box_max": hi.tolist(),
            "source": src, "percentile": pct, "formula": "x_canonical = scale * (x - centre)"}


def apply_normalization(norm: dict, cams: Cameras) -> Cameras:
    """``cams`` moved into the canonical frame of ``norm``."""
    s = float(norm["scale"])
    return cams.transformed(s, None, -s * np.asarray(norm["centre"], np.float64))


def original_cameras(cams: Cameras, records: dict) -> tuple[Cameras, list[str]]:
    """The same cameras for the ORIGINAL photos (full resolution, upright): cameras + absolute paths.

    Intrinsics are scaled per axis by the ratio of original to working size recorded
    by ingest; for an import stage (no working copies), by the ratio of the photo's own size (recorded by
    :func:`curate.sfm.pose_import.check_photos`) to the size the poses describe: poses written for 1080x1920 and
    photos at 180x320 (nerfstudio's ``images_4``) export cameras of the 180x320 photos.
    """
    by_name = {r["working"]: r for r in records.get("photos", []) if r.get("working")}
    imported = {r["rel"]: r for r in records.get("photos", []) if not r.get("working") and r.get("rel")}
    fx, fy, cx, cy, w, h, paths = [], [], [], [], [], [], []
    for i, n in enumerate(cams.names):
        r = by_name.get(n)
        if r is None and n in imported:  # an import: the pose's intrinsics, scaled to its photo's own size
            rec = imported[n]
            ow, oh = rec.get("orig_width") or cams.width[i], rec.get("orig_height") or cams.height[i]
            r = {"scale_x": cams.width[i] / ow, "scale_y": cams.height[i] / oh, "orig_width": ow, "orig_height": oh,
                 "original": rec["original"] if Path(rec["original"]).is_absolute() else ""}
        sx = 1.0 / r["scale_x"] if r else 1.0
        sy = 1.0 / r["scale_y"] if r else 1.0
        fx.append(cams.fx[i] * sx)
        cx.append(cams.cx[i] * sx)
        fy.append(cams.fy[i] * sy)
        cy.append(cams.cy[i] * sy)
        w.append(r["orig_width"] if r else cams.width[i])
        h.append(r["orig_height"] if r else cams.height[i])
        paths.append(r["original"] if r else n)
    return Cameras(cams.c2w, np.array(fx), np.array(fy), np.array(cx), np.array(cy), np.array(w), np.array(h),
                   cams.dist, cams.names), paths


def image_paths(run_dir: str | Path, names: list[str], records: dict) -> list[str]:
    """The image file of each registered camera ``names``: the SfM working copy, else the original photo."""
    run_dir = Path(run_dir)
    by: dict[str, tuple[str, dict]] = {}
    for r in records.get("photos", []):
        if r.get("working"):
            by[r["working"]] = ("working", r)
        if r.get("rel"):
            by.setdefault(r["rel"], ("original", r))
    out = []
    for n in names:
        if n not in by:
            raise FileNotFoundError(f"no photo recorded for camera {n!r} in {run_dir}/sfm/images.json")
        kind, r = by[n]
        out.append(str(RunPaths(run_dir).working_images / n) if kind == "working" else
                   known_original(r["original"], run_dir))
    return out


def known_original(original: str, run_dir: str | Path) -> str:
    """``original``, a photo recorded in ``images.json``; ``FileNotFoundError`` when it is a bare name: the import
    found no photo for that pose (a COLMAP model read without its photo folder keeps its image names), and a bare
    name is never looked up in the working directory."""
    if not Path(original).is_absolute():
        raise FileNotFoundError(f"{RunPaths(run_dir).images_json}: no photo was found for the pose of {original!r} "
                                "(the poses were read without their photo folder): run again with it: curate run "
                                "PHOTOS --poses ...")
    return original


def images_txt_rows(path: str | Path, errors: str = "strict") -> list[tuple[str, list[float], list[float], int]]:
    """(name, [4] quaternion QW QX QY QZ as written, [3] translation, camera id) of each image of a COLMAP
    ``images.txt``; ValueError naming the file and line on a malformed image line (``errors``: how bytes that are
    not UTF-8 are decoded, as :meth:`str.decode` takes it)."""
    path = Path(path)
    lines = [ln for ln in path.read_text(errors=errors).splitlines() if not ln.startswith("#")]
    rows = []
    i = 0
    while i < len(lines):
        ln = lines[i].strip()
        if not ln:
            i += 1
            continue
        parts = ln.split()
        try:
            if len(parts) < 10:
                raise ValueError
            vals = [float(v) for v in parts[1:8]]
            cid = int(parts[8])
        except ValueError:
            raise ValueError(f"{path}: not an image line of COLMAP's images.txt: {ln!r}") from None
        rows.append((" ".join(parts[9:]), vals[:4], vals[4:], cid))
        i += 2                                   # the POINTS2D line (possibly empty) follows each image line
    return rows
