"""A feature-rich object capture: the rendered object orbit with real photographs as every surface (issue 52).

    python -m research.feature_rich --textures ../shared/data/office/images ../shared/data/fox/images \\
        --n 300 --work /tmp/curate_feature_rich [--mappers global] [--jobs 2]

The project's procedural textures give a fraction of a real photo's SIFT features and tracks, so its
rendered 300-photo object maps in 35 s where a real one took 33 minutes. Here the living room of
:func:`curate.simulate.synthetic.make_scene` keeps its geometry and lights, and every solid's albedo is a
real photograph (from ``--textures``, one per solid, in turn), mapped on the surface by the axis its normal
is nearest (boxes: the face; cylinders: the caps, else around the axis; spheres: the nearest axis), one
photo width per ``--tex-metres`` metres, repeated. The capture is
:func:`research.bench.bench_mapping.object_orbit`: ``--n`` photos of 800x533 in three rings around the
coffee table, named ``IMG_0001.jpg``... (sequential matching, as a phone's photos get). Rendered once
(cached, resumable); then ``curate sfm`` on it (:func:`research.bench.bench_mapping.run_sfm`: stage times,
peak memory, pose errors against the rendered truth) and each of ``--mappers`` on the same matches
(:func:`research.bench.bench_mapping.run_map`). Prints one JSON object: the capture's features per image,
mean track length and points beside the SfM record and the mappers'.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
from pathlib import Path

import numpy as np

from curate.simulate.synthetic import Scene, make_scene

TEX_SIDE = 1024


@dataclasses.dataclass
class PhotoScene(Scene):
    """A :class:`Scene` whose solids are textured with photographs (``textures``: [H, W, 3] linear RGB)."""

    textures: list = dataclasses.field(default_factory=list)
    tex_metres: float = 1.0

    def _albedo(self, p: np.ndarray, gid: np.ndarray) -> np.ndarray:
        out = np.zeros((p.shape[0], 3))
        for g in np.unique(gid):
            sel = gid == g
            s = self.solids[int(g)]
            out[sel] = _sample(self.textures[int(g) % len(self.textures)], _uv(s, p[sel]) / self.tex_metres)
        return out


def _uv(solid, p: np.ndarray) -> np.ndarray:
    """[n, 2] surface coordinates (metres) of points [n, 3] on ``solid``: the two axes other than the one its
    normal is nearest to (a cylinder's side: arc length around the axis and height)."""
    lo, hi = np.asarray(solid.lo, float), np.asarray(solid.hi, float)
    if solid.kind == "box":
        d = np.minimum(np.abs(p - lo), np.abs(p - hi))                  # [n, 3] distance to each pair of faces
        ax = np.argmin(d, axis=1)
    elif solid.kind == "cylinder":
        r, h = hi[0], hi[2]
        cap = np.minimum(np.abs(p[:, 2] - lo[2]), np.abs(p[:, 2] - lo[2] - h)) < 1e-3
        ang = np.arctan2(p[:, 1] - lo[1], p[:, 0] - lo[0])
        side = np.stack([ang * r, p[:, 2]], 1)
        return np.where(cap[:, None], p[:, :2], side)
    else:
        ax = np.argmax(np.abs(p - lo), axis=1)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[ax]                       # [n, 2] the other two axes
    return np.take_along_axis(p, keep, axis=1)


def _sample(tex: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """[n, 3] bilinear samples of ``tex`` [H, W, 3] at ``uv`` [n, 2] (one texture width per unit, repeated)."""
    H, W = tex.shape[:2]
    x, y = (uv[:, 0] * W) % W, (uv[:, 1] * W) % H
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = (x0 + 1) % W, (y0 + 1) % H
    return ((1 - fx) * (1 - fy) * tex[y0, x0] + fx * (1 - fy) * tex[y0, x1] + (1 - fx) * fy * tex[y1, x0]
            + fx * fy * tex[y1, x1])


def load_textures(folders: list[Path], per_folder: int = 12) -> list[np.ndarray]:
    """Up to ``per_folder`` photos of each folder (evenly through its sorted JPEGs), at most ``TEX_SIDE`` px,
    as linear RGB in [0, 1]."""
    from PIL import Image, ImageOps
    out = []
    for f in folders:
        files = sorted(q for q in Path(f).iterdir() if q.suffix.lower() in (".jpg", ".jpeg", ".png"))
        for q in files[:: max(1, len(files) // per_folder)][:per_folder]:
            with Image.open(q) as im:
                im = ImageOps.exif_transpose(im).convert("RGB")
                im.thumbnail((TEX_SIDE, TEX_SIDE))
                out.append((np.asarray(im, np.float64) / 255.0) ** 2.2)
    if not out:
        raise SystemExit("no texture photos found")
    return out


_SCENE: dict = {}


def photo_scene(textures: tuple[str, ...], tex_metres: float) -> PhotoScene:
    key = (textures, tex_metres)
    if key not in _SCENE:
        base = make_scene("livingroom", 0)
        kw = {f.name: getattr(base, f.name) for f in dataclasses.fields(Scene)}
        _SCENE[key] = PhotoScene(**kw, textures=load_textures([Path(t) for t in textures]), tex_metres=tex_metres)
    return _SCENE[key]


def _render_chunk(args) -> int:
    textures, tex_metres, n, folder, idx, width = args
    from PIL import Image
    from research.bench.bench_mapping import object_orbit
    scene = photo_scene(textures, tex_metres)
    cams = object_orbit(n, 0, width=width, height=round(width * 533 / 800))
    for i in idx:
        rgb, _ = scene.render(cams[int(i)])
        dst = Path(folder) / cams.names[i]
        Image.fromarray(rgb[0]).save(str(dst) + ".part.jpg", quality=92)
        os.replace(str(dst) + ".part.jpg", dst)
    return len(idx)


def render(work: Path, textures: list[str], tex_metres: float, n: int, jobs: int, width: int = 800) -> Path:
    """The capture's folder (``object_photo_s0_n<n>``, named so bench_mapping's truth reader finds the seed;
    ``_w<width>`` added past 800 pixels)."""
    from multiprocessing import Pool
    from research.bench.bench_mapping import object_orbit
    folder = work / "frames" / (f"object_photo_s0_n{n}" + (f"_w{width}" if width != 800 else ""))
    folder.mkdir(parents=True, exist_ok=True)
    cams = object_orbit(n, 0, width=width, height=round(width * 533 / 800))
    np.save(folder / "truth.npy", cams.c2w)
    todo = [i for i in range(n) if not (folder / cams.names[i]).is_file()]
    chunks = [(tuple(textures), tex_metres, n, str(folder), todo[a:a + 5], width) for a in range(0, len(todo), 5)]
    done = 0
    if chunks:
        with Pool(jobs) as pool:
            for k in pool.imap(_render_chunk, chunks):
                done += k
                print(f"rendered {done}/{len(todo)}", file=sys.stderr, flush=True)
    return folder


def capture_figures(run: Path) -> dict:
    """Features per image, points, mean track length and observations per image of ``RUN``'s SfM."""
    import pycolmap
    sfm = run / "sfm"
    rec = pycolmap.Reconstruction(str(sfm / "sparse" / "0"))
    from research.rundb import database_copy
    with database_copy(sfm / "database.db") as copy, pycolmap.Database.open(copy) as db:
        n_img, n_kp = db.num_images(), db.num_keypoints()
    return {"features_per_image": round(n_kp / max(n_img, 1), 1), "points": int(rec.num_points3D()),
            "mean_track_length": round(float(rec.compute_mean_track_length()), 2),
            "observations_per_image": round(float(rec.compute_mean_observations_per_reg_image()), 1)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--textures", nargs="+", required=True, help="folders of photos used as textures")
    ap.add_argument("--tex-metres", type=float, default=2.0)
    ap.add_argument("--n", type=int, default=300)
    ap.add_argument("--work", type=Path, default=Path("/tmp/curate_feature_rich"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--mappers", nargs="*", default=[])
    ap.add_argument("--sfm-args", nargs="*", default=[], help="extra `curate sfm` flags")
    ap.add_argument("--render-only", action="store_true")
    ap.add_argument("--width", type=int, default=800, help="photo width (height 2/3 of it); 1600: the full SIFT "
                    "budget's features")
    a = ap.parse_args(argv)
    from research.bench.bench_mapping import run_map, run_sfm
    frames = render(a.work, [str(Path(t).resolve()) for t in a.textures], a.tex_metres, a.n, a.jobs, a.width)
    if a.render_only:
        return 0
    (a.work / "results").mkdir(parents=True, exist_ok=True)
    name = f"object_photo_{a.n}" + ("_" + "_".join(x.strip("-") for x in a.sfm_args) if a.sfm_args else "")
    out = {"sfm": run_sfm(a.work, name, frames, frames, "object", a.sfm_args, False)}
    if out["sfm"].get("process", {}).get("rc") == 0:
        out["capture"] = capture_figures(a.work / "runs" / name)
        for m in a.mappers:
            out[f"map_{m}"] = run_map(a.work, name, m, frames, "object", False)
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
