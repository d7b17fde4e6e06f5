"""Read and write NeRF ``transforms.json`` files (instant-ngp, nerfstudio, Blender-synthetic).

Poses in the file are OpenGL/NeRF camera-to-world (x right, y up, z backward);
they are converted to the project's OpenCV camera-to-world on reading and back on
writing (``curate.core.cameras.opencv_from_opengl``).

Intrinsics may be global (top level) or per frame (a frame's keys win):
``fl_x fl_y cx cy w h``, or ``camera_angle_x`` (and optionally ``camera_angle_y``)
for a field of view; ``k1 k2 p1 p2`` distortion. Missing ``w``/``h`` are read from
the image header; a missing principal point is the image centre.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras, opencv_from_opengl, opengl_from_opencv
from curate.core.paths import inside, within_capture

_IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".PNG", ".JPG", ".JPEG", ".tif", ".tiff")


def _resolve_image(root: Path, file_path: str) -> Path | None:
    p = (root / file_path)
    if p.suffix and p.exists():
        return p
    for ext in _IMAGE_EXTS:
        q = p.with_name(p.name + ext)
        if q.exists():
            return q
    return p if p.exists() else None


def _image_size(path: Path | None) -> tuple[int, int] | None:
    if path is None:
        return None
    from PIL import Image
    with Image.open(path) as im:
        return im.size


CAMERA_MODELS = ("OPENCV", "PINHOLE", "SIMPLE_PINHOLE")
"""transforms.json ``camera_model`` values :func:`read_transforms` reads: perspective cameras, with OpenCV's k1 k2 p1 p2
(no value: the same)."""


FIELDS = {"c2w": "transform_matrix", "centre": "transform_matrix's translation", "fx": "fl_x", "fy": "fl_y",
          "width": "w", "height": "h", "dist": "k1 k2 p1 p2"}
"""The fields of a transforms.json, as :func:`curate.core.cameras.check_poses` names them."""


def _angle(v, key: str) -> float:
    """A field of view in radians (``camera_angle_x``/``_y``): ValueError naming ``key`` unless a perspective
    camera can have it (:data:`curate.core.cameras.MIN_FOV_DEG` to :data:`~curate.core.cameras.MAX_FOV_DEG`)."""
    from curate.core.cameras import MAX_FOV_DEG, MIN_FOV_DEG
    a = float(v)
    if not math.radians(MIN_FOV_DEG) <= a <= math.radians(MAX_FOV_DEG):
        raise ValueError(f"{key} = {a:g} ({math.degrees(a) if math.isfinite(a) else a:.4g} degrees): a perspective "
                         f"camera's field of view is between {MIN_FOV_DEG:g} and {MAX_FOV_DEG:g} degrees")
    return a


def read_transforms(path: str | Path, photos: str | Path | None = None, contained: bool = True
                    ) -> tuple[Cameras, list[str]]:
    """Read a transforms.json.

    ``photos``: a folder where a frame without ``w``/``h`` finds its image when it is not at its ``file_path``
    beside the file (by that path in the folder, else by its file name), to read its size from.

    Returns:
        cameras: OpenCV c2w cameras, ``names`` = each frame's ``file_path`` as written.
        file_paths: absolute paths of the frames' images (resolved against the json's folder;
            an extension is added when the file path has none, as Blender-synthetic files do). Without
            ``photos``, a file path that leaves the json's folder (``..``, an absolute path elsewhere, a link
            out) is a ``ValueError`` naming the file and the frame (:func:`curate.core.paths.within_capture`);
            with it, nothing outside the json's folder or ``photos`` is opened. ``contained=False`` (curate's
            own outputs only, such as ``curate select``'s, whose paths climb to the photos) lifts the check.
    """
    path = Path(path)
    try:
        meta = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise ValueError(f"{path}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    except RecursionError:
        raise ValueError(f"{path}: not a transforms.json: its JSON is nested too deeply to read") from None
    if not isinstance(meta, dict):
        raise ValueError(f"{path}: not a transforms.json (a JSON object with 'frames')")
    frames = meta.get("frames")
    if not isinstance(frames, list) or not frames:
        raise ValueError(f"{path}: no 'frames' list")
    models = {m for m in [meta.get("camera_model")] + [fr.get("camera_model") for fr in frames if isinstance(fr, dict)]
              if m is not None}
    odd = sorted(str(m) for m in models if str(m).upper() not in CAMERA_MODELS)
    if odd:     # a fisheye or 360 camera read as a perspective one would be a silent wrong result
        raise ValueError(f"{path}: camera_model {odd[0]!r} is not one curate reads ({', '.join(CAMERA_MODELS)}): "
                         "undistort the photos to a perspective camera first (COLMAP's image_undistorter)")
    root = path.parent
    c2w, fx, fy, cx, cy, ws, hs, dist, names, files = [], [], [], [], [], [], [], [], [], []
    for i, fr in enumerate(frames):
        fp = str(fr.get("file_path", "")) if isinstance(fr, dict) else ""
        try:
            if "transform_matrix" not in fr:
                raise ValueError(f"{path}: frame {i} has no transform_matrix")
            get = lambda k, fr=fr: fr.get(k, meta.get(k))  # noqa: E731
            fp = str(fr.get("file_path", ""))
            if contained and photos is None and fp:   # the file's own folder is the capture's: nothing outside
                within_capture(root, fp, path, f"frame {i}")
            img = _resolve_image(root, fp) if fp and (inside(root / fp, root) or not contained) else None
            if contained and img is not None and not inside(img, root):   # the extension added: a link out
                within_capture(root, str(img.relative_to(root)), path, f"frame {i}")
            w, h = get("w"), get("h")
            if w is None or h is None:
                if img is None and photos is not None and fp:     # the photo folder the user gave
                    img = next((q for q in (_resolve_image(Path(photos), fp),
                                            _resolve_image(Path(photos), Path(fp).name))
                                if q is not None and inside(q, photos)), None)
                size = _image_size(img)
                if size is None:
                    raise ValueError(f"{path}: frame {i} ({fp!r}) has no w and h, and its image was not found to "
                                     "read them from: add \"w\" and \"h\" (the image size in pixels) to the file, "
                                     "or give the photo folder")
                w, h = size
            w, h = float(w), float(h)
            if get("fl_x") is not None:
                f_x = float(get("fl_x"))
                f_y = float(get("fl_y")) if get("fl_y") is not None else f_x
            elif get("camera_angle_x") is not None:
                f_x = 0.5 * w / math.tan(0.5 * _angle(get("camera_angle_x"), "camera_angle_x"))
                f_y = (0.5 * h / math.tan(0.5 * _angle(get("camera_angle_y"), "camera_angle_y"))
                       if get("camera_angle_y") is not None else f_x)
            else:
                raise ValueError(f"{path}: frame {i} has neither fl_x nor camera_angle_x")
            try:
                m = np.asarray(fr["transform_matrix"], np.float64)
                w, h = float(w), float(h)
            except (TypeError, ValueError):
                raise ValueError(f"{path}: frame {i} ({fp!r}) has a transform_matrix or size "
                                 "that is not numbers") from None
            if m.shape == (3, 4):
                m = np.vstack([m, [0, 0, 0, 1]])
            if m.shape != (4, 4):
                raise ValueError(f"{path}: frame {i} transform_matrix has shape {m.shape}")
            c2w.append(m)
            fx.append(f_x)
            fy.append(f_y)
            cx.append(float(get("cx")) if get("cx") is not None else 0.5 * w)
            cy.append(float(get("cy")) if get("cy") is not None else 0.5 * h)
            ws.append(int(round(w)))
            hs.append(int(round(h)))
            dist.append([float(get(k)) if get(k) is not None else 0.0 for k in ("k1", "k2", "p1", "p2")])
            names.append(fp)
            files.append(str(img) if img is not None else str(root / fp))
        except (TypeError, ValueError, KeyError, AttributeError, OverflowError) as e:
            if str(e).startswith(str(path)):
                raise
            said = str(e) if isinstance(e, ValueError) else f"{type(e).__name__}: {e}"
            raise ValueError(f"{path}: frame {i} ({fp!r}): {said}") from None

    from curate.core.cameras import check_poses
    check_poses(np.stack(c2w), fx, fy, cx, cy, ws, hs, names, str(path), dist=np.array(dist), fields=FIELDS)
    dup = sorted({f for f in files if files.count(f) > 1})
    if dup:
        raise ValueError(f"{path}: {len(dup)} image file(s) appear in more than one frame, e.g. {dup[0]}")
    cams = Cameras(opencv_from_opengl(np.stack(c2w)), np.array(fx), np.array(fy), np.array(cx), np.array(cy),
                   np.array(ws), np.array(hs), np.array(dist), tuple(names))
    return cams, files


def transforms_dict(cams: Cameras, file_paths: list[str] | None = None, extra: dict | None = None) -> dict:
    """nerfstudio / instant-ngp transforms.json content for ``cams``.

    Intrinsics go to the top level when all cameras share them (instant-ngp reads
    only those), else per frame (nerfstudio reads both). ``camera_model`` is
    ``OPENCV`` when any distortion is non-zero, else ``PINHOLE``.
    """
    file_paths = list(cams.names) if file_paths is None else list(file_paths)
    if len(file_paths) != len(cams):
        raise ValueError("one file path per camera is needed")
    intr = np.stack([cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height], axis=1)
    intr = np.concatenate([intr, cams.dist], axis=1)
    keys = ("fl_x", "fl_y", "cx", "cy", "w", "h", "k1", "k2", "p1", "p2")
    shared = len(cams) > 0 and bool(np.all(intr == intr[0]))
    has_dist = bool(np.any(cams.dist != 0))

    def intr_of(row) -> dict:
        d = {k: float(v) for k, v in zip(keys, row)}
        d["w"], d["h"] = int(d["w"]), int(d["h"])
        if not has_dist:
            for k in keys[6:]:
                d.pop(k)
        return d

    out: dict = {"camera_model": "OPENCV" if has_dist else "PINHOLE"}
    if shared:
        out.update(intr_of(intr[0]))
        out["camera_angle_x"] = float(2 * math.atan(0.5 * cams.width[0] / cams.fx[0]))
        out["camera_angle_y"] = float(2 * math.atan(0.5 * cams.height[0] / cams.fy[0]))
    gl = opengl_from_opencv(cams.c2w)
    frames = []
    for i in range(len(cams)):
        fr = {"file_path": file_paths[i], "transform_matrix": gl[i].tolist()}
        if not shared:
            fr.update(intr_of(intr[i]))
        frames.append(fr)
    out["frames"] = frames
    if extra:
        out.update(extra)
    return out


def write_transforms(path: str | Path, cams: Cameras, file_paths: list[str] | None = None,
                     extra: dict | None = None) -> Path:
    """Write ``cams`` as a transforms.json; returns the path."""
    from curate.core.stage import writing
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with writing(path):
        path.write_text(json.dumps(transforms_dict(cams, file_paths, extra), indent=2))
    return path
