"""Loaders for the ground-truth poses of the sample data sets (tests and benchmarks).

* Middlebury multi-view (``templeR_par.txt``, ``dinoR_par.txt``...): first line the
  number of images, then per image ``name k11..k33 r11..r33 t1 t2 t3`` with
  ``P = K [R | t]`` world-to-camera, OpenCV axes.
* office (DeepVideoMVS-style): ``poses.txt`` one row-major 4x4 OpenCV camera-to-world
  per image, in sorted image-name order; ``K.txt`` a 3x3 intrinsic matrix.
* fox / any transforms.json: ``curate.core.transforms_json.read_transforms``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras, c2w_from_w2c

_IMG = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}


def _size(path: Path) -> tuple[int, int]:
    from PIL import Image
    with Image.open(path) as im:
        return im.size


def rotate_calibration_ccw(cams: Cameras) -> Cameras:
    """The cameras of images rotated 90 degrees counter-clockwise (the right edge goes to the top).

    An original pixel ``(u, v)`` of a ``W x H`` image lands at ``(v, W - u)`` of the
    ``H x W`` rotated image: new camera axes ``x' = y``, ``y' = -x``; ``fx' = fy``,
    ``fy' = fx``, ``cx' = cy``, ``cy' = W - cx``.
    """
    c2w = cams.c2w.copy()
    c2w[:, :3, 0], c2w[:, :3, 1] = cams.c2w[:, :3, 1], -cams.c2w[:, :3, 0]
    return Cameras(c2w, cams.fy, cams.fx, cams.cy, cams.width - cams.cx, cams.height, cams.width,
                   names=cams.names)


def load_middlebury(par_file: str | Path, image_dir: str | Path | None = None,
                    rotated_ccw: bool | None = None) -> Cameras:
    """Cameras of a Middlebury ``*_par.txt`` file; names are the image file names.

    Image sizes are read from the images in ``image_dir`` (default: the file's folder),
    falling back to 640x480 when an image is missing.

    ``rotated_ccw``: the stored images are the calibrated ones turned 90 degrees
    counter-clockwise (our copy of templeRing is: its PNGs are 480x640 portrait, upright
    temple, while ``K`` and ``R`` describe the original 640x480 landscape frames; checked
    against SfM, see tests/test_sfm.py). ``None`` detects it: the images are portrait
    and the principal point is much nearer the centre of the transposed size.
    """
    par_file = Path(par_file)
    image_dir = Path(image_dir) if image_dir is not None else par_file.parent
    lines = [ln.split() for ln in par_file.read_text().splitlines() if ln.strip()]
    if len(lines[0]) == 1:
        n = int(lines[0][0])
        lines = lines[1:]
        if len(lines) != n:
            raise ValueError(f"{par_file}: header says {n} images, found {len(lines)}")
    names, K, R, t, w, h = [], [], [], [], [], []
    for ln in lines:
        if len(ln) != 22:
            raise ValueError(f"{par_file}: expected 22 fields per line, got {len(ln)}")
        v = np.array(ln[1:], np.float64)
        names.append(ln[0])
        K.append(v[:9].reshape(3, 3))
        R.append(v[9:18].reshape(3, 3))
        t.append(v[18:21])
        p = image_dir / ln[0]
        ww, hh = _size(p) if p.is_file() else (640, 480)
        w.append(ww)
        h.append(hh)
    K = np.stack(K)
    w, h = np.array(w), np.array(h)
    if rotated_ccw is None:
        off = np.abs(K[:, 0, 2] - w / 2) + np.abs(K[:, 1, 2] - h / 2)
        off_t = np.abs(K[:, 0, 2] - h / 2) + np.abs(K[:, 1, 2] - w / 2)
        rotated_ccw = bool(np.all(h > w) and np.median(off_t) < 0.5 * np.median(off))
    if rotated_ccw:  # calibration is for the W x H = h x w original
        cams = Cameras(c2w_from_w2c(np.stack(R), np.stack(t)), K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2],
                       h, w, names=tuple(names))
        return rotate_calibration_ccw(cams)
    return Cameras(c2w_from_w2c(np.stack(R), np.stack(t)), K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2],
                   w, h, names=tuple(names))


def roll_upright(cams: Cameras) -> Cameras:
    """Turn by 180 degrees (about the optical axis) the cameras whose image is upside down.

    "Up" is the normal of the plane of the camera centres (a ring or dome around the
    object), signed so that most cameras already have it pointing to the image top.
    A camera with its image "up" (-y axis) against it is rolled: ``x, y -> -x, -y``,
    ``cx -> W - cx``, ``cy -> H - cy``.
    """
    c = cams.centres - cams.centres.mean(0)
    n = np.linalg.svd(c, full_matrices=False)[2][2]
    up_dot = -cams.c2w[:, :3, 1] @ n
    if np.sum(up_dot < 0) > np.sum(up_dot > 0):
        up_dot = -up_dot
    flip = up_dot < 0
    c2w = cams.c2w.copy()
    c2w[flip, :3, :2] *= -1
    cx = np.where(flip, cams.width - cams.cx, cams.cx)
    cy = np.where(flip, cams.height - cams.cy, cams.cy)
    return Cameras(c2w, cams.fx, cams.fy, cx, cy, cams.width, cams.height, cams.dist, cams.names)


def load_templering(folder: str | Path) -> Cameras:
    """The Middlebury templeRing set: ``folder/templeR_par.txt`` with its PNGs.

    Our copy (``shared/data/templering``) shows every image upright, 480x640, while the
    calibration describes the original frames: 640x480, and for the negative-latitude
    views upside down (the set's README: "(lat, lon) corresponds to the same image as
    (-lat, 180 + lon), rotated 180 degrees"). So the calibration is turned 90 degrees
    (``rotated_ccw`` detection) and then 180 degrees for the views that are upside down
    (``roll_upright``): 16 of the 47. Checked against SfM of the images (all within ~1.3 deg).
    """
    cams = load_middlebury(Path(folder) / "templeR_par.txt", folder)
    return roll_upright(cams)


def load_office(folder: str | Path) -> Cameras:
    """office: ``poses.txt`` (OpenCV c2w per image, sorted name order) + ``K.txt``; images in ``folder/images``."""
    folder = Path(folder)
    imgs = sorted(p for p in (folder / "images").iterdir() if p.suffix.lower() in _IMG)
    poses = np.loadtxt(folder / "poses.txt", dtype=np.float64).reshape(-1, 4, 4)
    if len(poses) != len(imgs):
        raise ValueError(f"{folder}: {len(poses)} poses for {len(imgs)} images")
    K = np.loadtxt(folder / "K.txt", dtype=np.float64).reshape(3, 3)
    w, h = _size(imgs[0])
    return Cameras(poses, K[0, 0], K[1, 1], K[0, 2], K[1, 2], w, h, names=tuple(p.name for p in imgs))


def load_ground_truth(folder: str | Path) -> Cameras | None:
    """Ground truth for one of the sample folders (fox, templering, office), or None when it has none."""
    folder = Path(folder)
    if (folder / "transforms.json").is_file():
        from curate.core.transforms_json import read_transforms
        return read_transforms(folder / "transforms.json")[0]
    if (folder / "templeR_par.txt").is_file():
        return load_templering(folder)
    par = sorted(folder.glob("*_par.txt"))
    if par:
        return load_middlebury(par[0])
    if (folder / "poses.txt").is_file() and (folder / "K.txt").is_file():
        return load_office(folder)
    return None


def image_folder(folder: str | Path) -> Path:
    """The folder holding a sample set's photos: ``folder/images`` when it exists, else ``folder``."""
    folder = Path(folder)
    return folder / "images" if (folder / "images").is_dir() else folder
