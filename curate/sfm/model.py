"""COLMAP models and curate's cameras: a ``pycolmap.Reconstruction`` to :class:`curate.core.cameras.Cameras`
and back, and a COLMAP model folder read as known poses (its quaternions checked before pycolmap normalises them).
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras
from curate.sfm.io import colmap_from_intrinsics, intrinsics_from_colmap
from curate.sfm.native import load as load_pycolmap

logger = logging.getLogger(__name__)


@dataclass
class Poses:
    """Cameras read from a pose source."""

    cameras: Cameras
    """[N] cameras (OpenCV camera-to-world)."""
    files: list[str]
    """[N] image path of each camera (absolute where it could be resolved)."""
    points: np.ndarray | None = None
    """[P, 3] sparse points (COLMAP model only)."""
    colors: np.ndarray | None = None
    """[P, 3] uint8 colours of the points."""
    errors: np.ndarray | None = None
    """[P] reprojection errors of the points."""
    reconstruction: object | None = None
    """The ``pycolmap.Reconstruction`` (COLMAP model only)."""


def cameras_from_reconstruction(rec, warn: bool = True) -> tuple[Cameras, np.ndarray, np.ndarray, np.ndarray]:
    """Registered images of a ``pycolmap.Reconstruction`` as project cameras, sorted by name.

    A camera model the project does not hold (fisheye, ...) keeps its pinhole part; that is
    logged as one warning per model with the count of images (``warn``; off for the mapper's
    internal comparisons, which read the same models again).

    pycolmap 4 exposes ``image.cam_from_world()`` (a ``Rigid3d``, world-to-camera); its
    rotation is read as a matrix (``rotation.matrix()``), avoiding the quaternion order
    question (pycolmap stores Eigen ``x y z w``, COLMAP's text files ``w x y z``).

    Returns:
        cameras, points [P, 3] float32, colours [P, 3] uint8, errors [P] float32.
    """
    from curate.core.cameras import c2w_from_w2c

    ids = sorted(rec.reg_image_ids(), key=lambda i: rec.image(i).name)
    R, t, fx, fy, cx, cy, w, h, dist, names = [], [], [], [], [], [], [], [], [], []
    pinhole_only: dict[str, list[str]] = {}           # unsupported model's message -> its images: one line each
    for i in ids:
        im = rec.image(i)
        T = im.cam_from_world()
        R.append(np.asarray(T.rotation.matrix(), np.float64))
        t.append(np.asarray(T.translation, np.float64))
        cam = rec.camera(im.camera_id)
        try:
            f_x, f_y, c_x, c_y, d = intrinsics_from_colmap(cam.model_name, cam.params)
        except ValueError as e:
            pinhole_only.setdefault(str(e), []).append(im.name)
            f_x, f_y, c_x, c_y, d = cam.focal_length_x, cam.focal_length_y, cam.principal_point_x, \
                cam.principal_point_y, np.zeros(4)
        fx.append(f_x), fy.append(f_y), cx.append(c_x), cy.append(c_y), dist.append(d)
        w.append(cam.width), h.append(cam.height), names.append(im.name)
    if warn:
        for msg, ims in pinhole_only.items():
            logger.warning("%d of %d images (%s%s): %s; using the pinhole part only", len(ims), len(ids),
                           ", ".join(ims[:3]), ", ..." if len(ims) > 3 else "", msg)
    if not ids:
        cams = Cameras.empty()
    else:
        cams = Cameras(c2w_from_w2c(np.stack(R), np.stack(t)), np.array(fx), np.array(fy), np.array(cx),
                       np.array(cy), np.array(w), np.array(h), np.array(dist), tuple(names))
    pts3 = list(rec.points3D.values())
    if pts3:
        xyz = np.array([p.xyz for p in pts3], np.float32)
        rgb = np.array([p.color for p in pts3], np.uint8)
        err = np.array([p.error for p in pts3], np.float32)
    else:
        xyz, rgb, err = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), np.zeros(0, np.float32)
    return cams, xyz, rgb, err


def reconstruction_from_cameras(cams: Cameras, keypoints: list | None = None, image_ids: list[int] | None = None,
                                camera_ids: list[int] | None = None):
    """A ``pycolmap.Reconstruction`` holding ``cams`` (no points); cameras with equal intrinsics share one.

    ``keypoints``: per camera, its [K_i, 2] keypoints (pixels) or None. ``image_ids`` / ``camera_ids``:
    per camera, the COLMAP ids to use (default: ``i + 1``, and one per distinct intrinsics).
    """
    pycolmap = load_pycolmap()

    from curate.core.cameras import w2c_from_c2w

    rec = pycolmap.Reconstruction()
    Rw, tw = w2c_from_c2w(cams.c2w)
    cam_ids: dict = {}
    for i in range(len(cams)):
        model, params = colmap_from_intrinsics(cams.fx[i], cams.fy[i], cams.cx[i], cams.cy[i], cams.dist[i])
        key = (model, tuple(params), int(cams.width[i]), int(cams.height[i]))
        if camera_ids is not None:
            key = (camera_ids[i],) + key
        if key not in cam_ids:
            cam_ids[key] = camera_ids[i] if camera_ids is not None else len(cam_ids) + 1
            rec.add_camera_with_trivial_rig(pycolmap.Camera(
                camera_id=cam_ids[key], model=model, width=key[-2], height=key[-1], params=params))
        kw = {} if keypoints is None or keypoints[i] is None else \
            {"keypoints": np.asarray(keypoints[i], np.float64).reshape(-1, 2)}
        im = pycolmap.Image(name=cams.names[i] or f"{i:06d}", camera_id=cam_ids[key],
                            image_id=image_ids[i] if image_ids is not None else i + 1, **kw)
        rec.add_image_with_trivial_frame(im, pycolmap.Rigid3d(pycolmap.Rotation3d(Rw[i]), tw[i]))
    return rec


def raw_quaternions(model: Path) -> list[tuple[Path, str, np.ndarray]]:
    """(file, image name, [4] quaternion as written) of every image of the model in ``model`` (``images.bin`` or
    ``images.txt``), before pycolmap normalises them; [] when neither is readable."""
    import struct
    out = []
    b, t = model / "images.bin", model / "images.txt"
    try:
        if b.is_file():
            data = b.read_bytes()
            (n,), o = struct.unpack_from("<Q", data, 0), 8
            for _ in range(n):
                q = np.array(struct.unpack_from("<4d", data, o + 4))
                o += 4 + 32 + 24 + 4
                end = data.index(b"\0", o)
                name = data[o:end].decode("utf-8", "replace")
                o = end + 1
                (k,) = struct.unpack_from("<Q", data, o)
                o += 8 + 24 * k
                out.append((b, name, q))
        elif t.is_file():
            from curate.sfm.io import images_txt_rows
            out = [(t, name, np.array(q)) for name, q, _, _ in images_txt_rows(t, errors="replace")]
    except (OSError, ValueError, struct.error, IndexError):
        return out      # a broken file: pycolmap has already said so, or reads what there is
    return out


def read_colmap_model(model: Path, photos: Path | None):
    """A COLMAP model folder as :class:`Poses`: image paths under ``photos`` when given, else the model's own folder's
    file where it has one (else the bare name: a camera without a photo), a name that leaves the folder being a
    ``ValueError`` naming ``images.bin``/``images.txt`` and the image."""
    pycolmap = load_pycolmap()
    try:
        rec = pycolmap.Reconstruction(model)
    except Exception as e:  # noqa: BLE001 - pycolmap raises its own error types
        said = re.sub(r"\[[\w./-]+:\d+\] Check failed: ", "COLMAP's check of ", str(e)).strip()
        raise ValueError(f"{model}: cannot read the COLMAP model ({said})") from None
    bad = [(f, n) for f, n, q in raw_quaternions(Path(model))
           if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-6)]
    if bad:   # pycolmap normalises a zero quaternion to the identity: a made-up pose, never a silent one
        raise ValueError(f"{bad[0][0]}: image {bad[0][1]} has a rotation quaternion of zero length or not finite "
                         f"({len(bad)} image(s)); fix or remove it")
    cams, xyz, rgb, err = cameras_from_reconstruction(rec)
    if photos is not None:   # looked up in the photo folder only (curate.sfm.poses.match_photos)
        files = [str((photos / n).resolve()) for n in cams.names]
    else:   # found in the model's own folder, else cameras without a photo; never outside the model's folder
        from curate.core.paths import within_capture
        images = Path(model) / ("images.bin" if (Path(model) / "images.bin").is_file() else "images.txt")
        found = [within_capture(model, n, images, "an image") for n in cams.names]
        files = [str(f.resolve()) if f.is_file() else n for f, n in zip(found, cams.names)]
    return Poses(cams, files, xyz, rgb, err, rec)


def pycolmap_reconstruction(path: str | Path):
    """The COLMAP model at ``path`` (pycolmap stays inside :mod:`curate.sfm`)."""
    pycolmap = load_pycolmap()
    return pycolmap.Reconstruction(str(path))
