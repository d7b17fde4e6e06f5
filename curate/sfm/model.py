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
    cams = Cameras.empty() if not (a := _arrays(rec, warn))["names"] else Cameras(
        a["c2w"], a["fx"], a["fy"], a["cx"], a["cy"], a["width"], a["height"], a["dist"], tuple(a["names"]))
    pts3 = list(rec.points3D.values())
    if pts3:
        xyz = np.array([p.xyz for p in pts3], np.float32)
        rgb = np.array([p.color for p in pts3], np.uint8)
        err = np.array([p.error for p in pts3], np.float32)
    else:
        xyz, rgb, err = np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint8), np.zeros(0, np.float32)
    return cams, xyz, rgb, err


def _arrays(rec, warn: bool = True) -> dict:
    """The registered images of ``rec``, sorted by name, as arrays (``c2w`` [N, 4, 4] OpenCV camera-to-world,
    ``fx`` ... ``height`` [N], ``dist`` [N, 4], ``names``), not yet checked (:func:`cameras_from_reconstruction`)."""
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
    with np.errstate(all="ignore"):
        c2w = c2w_from_w2c(np.stack(R), np.stack(t)) if ids else np.zeros((0, 4, 4))
    return {"c2w": c2w, "fx": np.array(fx, np.float64), "fy": np.array(fy, np.float64), "cx": np.array(cx, np.float64),
            "cy": np.array(cy, np.float64), "width": np.array(w, np.float64), "height": np.array(h, np.float64),
            "dist": np.array(dist, np.float64).reshape(-1, 4), "names": names}


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


MAX_SIDE = 1_000_000
"""Largest image width or height (pixels) a COLMAP camera may have (a negative width written to cameras.txt
is read by COLMAP as 2^32 - 320)."""


def _params_of(model_id: int) -> int | None:
    """How many parameters COLMAP's camera model ``model_id`` has (None: not a model COLMAP knows)."""
    pycolmap = load_pycolmap()
    try:
        mid = pycolmap.CameraModelId(int(model_id))
        if mid.name == "INVALID":
            return None
        return len(pycolmap.Camera.create_from_model_id(1, mid, 1.0, 2, 2).params)
    except (ValueError, TypeError, RuntimeError, AttributeError):
        return None


def _model_of(name: str) -> int | None:
    pycolmap = load_pycolmap()
    m = getattr(pycolmap.CameraModelId, name, None)
    return None if m is None or name == "INVALID" else int(m)


class _Bytes:
    """A reader of a COLMAP binary file that says, naming the file, where it is cut short."""

    def __init__(self, path: Path, what: str):
        self.path, self.what = path, what
        self.data = path.read_bytes()
        self.o = 0

    def take(self, fmt: str, where: str):
        import struct
        n = struct.calcsize(fmt)
        if self.o + n > len(self.data):
            raise ValueError(f"{self.path}: cut short ({len(self.data)} bytes) inside {where}: a truncated or "
                             f"damaged {self.what}; write it again with COLMAP")
        out = struct.unpack_from(fmt, self.data, self.o)
        self.o += n
        return out

    def name(self, where: str) -> str:
        end = self.data.find(b"\0", self.o)
        if end < 0:
            raise ValueError(f"{self.path}: cut short ({len(self.data)} bytes) inside {where}'s name: a truncated or "
                             f"damaged {self.what}; write it again with COLMAP")
        raw = self.data[self.o:end]
        self.o = end + 1
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError:
            return raw.decode("latin-1")

    def end(self) -> None:
        if self.o != len(self.data):
            raise ValueError(f"{self.path}: {len(self.data) - self.o} bytes after its last entry: a damaged "
                             f"{self.what} (or one of another format); write it again with COLMAP")


def _count(b: _Bytes, what: str, per_entry: int) -> int:
    (n,) = b.take("<Q", f"the number of {what}")
    if n * per_entry > len(b.data):
        raise ValueError(f"{b.path}: says it holds {n} {what}, more than its {len(b.data)} bytes can: a damaged "
                         f"{b.what}; write it again with COLMAP")
    return n


def _camera_sizes(path: Path, model_id_or_name, w, h, where: str) -> None:
    if not (1 <= w <= MAX_SIDE and 1 <= h <= MAX_SIDE):
        raise ValueError(f"{path}: {where}: WIDTH x HEIGHT = {w} x {h} is not an image size (1 to {MAX_SIDE} pixels)")


def check_model_files(model: Path) -> None:
    """ValueError, one line naming the file (and its line, or where it is cut short) and what is wrong, unless
    the COLMAP model in ``model`` is whole: the binary ``cameras.bin``, ``images.bin``, ``points3D.bin`` read to
    their last byte (an empty points3D.bin made COLMAP's reader fail with ``std::bad_alloc``; a truncated file with
    "unordered_map::at", or read on as zeros); the text ``cameras.txt``, ``images.txt`` with known camera models,
    their parameters, sizes and poses as numbers (a NaN quaternion made COLMAP name its own source line); and no
    image name twice. Checked before COLMAP reads the model."""
    import math
    from collections import Counter
    model = Path(model)
    names: list[str] = []
    if (model / "cameras.bin").is_file():
        b = _Bytes(model / "cameras.bin", "cameras.bin")
        for k in range(_count(b, "cameras", 24)):
            cid, mid, w, h = b.take("<iiQQ", f"camera {k + 1}")
            n = _params_of(mid)
            if n is None:
                raise ValueError(f"{b.path}: camera {cid}: camera model number {mid} is not one of COLMAP's: a damaged "
                                 "cameras.bin; write it again with COLMAP")
            _camera_sizes(b.path, mid, w, h, f"camera {cid}")
            params = b.take(f"<{n}d", f"camera {cid}'s parameters")
            if not all(math.isfinite(x) for x in params):
                raise ValueError(f"{b.path}: camera {cid}: its parameters {list(params)} hold NaN or infinite values")
        b.end()
        b = _Bytes(model / "images.bin", "images.bin") if (model / "images.bin").is_file() else None
        if b is not None:
            for k in range(_count(b, "images", 64)):
                iid, *pose = b.take("<I7d", f"image {k + 1}")
                (cid,) = b.take("<I", f"image {iid}")
                name = b.name(f"image {iid}")
                (n2d,) = b.take("<Q", f"image {iid} ({name!r})")
                b.take(f"<{3 * n2d}d" if n2d < len(b.data) else "<0d", f"image {iid}'s points")
                if n2d >= len(b.data):
                    raise ValueError(f"{b.path}: image {iid} ({name!r}) says it has {n2d} points, more than the file "
                                     "holds: a damaged images.bin; write it again with COLMAP")
                names.append(name)
            b.end()
        if (model / "points3D.bin").is_file():
            b = _Bytes(model / "points3D.bin", "points3D.bin")
            if not b.data:
                raise ValueError(f"{b.path}: empty (0 bytes): even a model without points holds their number (8 "
                                 "bytes); write it again with COLMAP, or delete it")
            for k in range(_count(b, "points", 51)):
                pid, *_ = b.take("<Q3d3Bd", f"point {k + 1}")
                (tl,) = b.take("<Q", f"point {pid}'s track")
                if tl * 8 > len(b.data):
                    raise ValueError(f"{b.path}: point {pid} says it has a track of {tl}, more than the file holds: a "
                                     "damaged points3D.bin; write it again with COLMAP")
                b.take(f"<{2 * tl}I", f"point {pid}'s track")
            b.end()
    elif (model / "cameras.txt").is_file():
        p = model / "cameras.txt"
        for no, ln in enumerate(p.read_text(errors="replace").splitlines(), 1):
            w_ = ln.split()
            if not w_ or ln.lstrip().startswith("#"):
                continue
            mid = _model_of(w_[1]) if len(w_) > 1 else None
            if mid is None:
                raise ValueError(f"{p}: line {no}: {w_[1] if len(w_) > 1 else ln.strip()!r} is not a camera model of "
                                 "COLMAP's (CAMERA_ID MODEL WIDTH HEIGHT PARAMS[])")
            n = _params_of(mid)
            try:
                cid, w, h = int(w_[0]), int(w_[2]), int(w_[3])
                params = [float(x) for x in w_[4:]]
            except (ValueError, IndexError):
                raise ValueError(f"{p}: line {no}: not CAMERA_ID MODEL WIDTH HEIGHT PARAMS[] as numbers: "
                                 f"{ln.strip()[:80]!r}") from None
            if len(params) != n:
                raise ValueError(f"{p}: line {no}: camera {cid} ({w_[1]}) has {len(params)} parameters; the model has "
                                 f"{n}")
            _camera_sizes(p, w_[1], w, h, f"line {no}: camera {cid}")
            if not all(math.isfinite(x) for x in params):
                raise ValueError(f"{p}: line {no}: camera {cid}'s parameters {params} hold NaN or infinite values")
        if (model / "images.txt").is_file():
            from curate.sfm.io import images_txt_rows
            for name, q, t, _ in images_txt_rows(model / "images.txt", errors="replace"):
                if not all(math.isfinite(x) for x in q + t):
                    raise ValueError(f"{model / 'images.txt'}: image {name!r}: its pose QW QX QY QZ TX TY TZ = "
                                     f"{q + t} holds NaN or infinite values")
                names.append(name)
    dup = [n for n, k in Counter(names).items() if k > 1]
    if dup:
        images = model / ("images.bin" if (model / "images.bin").is_file() else "images.txt")
        raise ValueError(f"{images}: {len(dup)} image name(s) appear more than once, e.g. {dup[0]!r}: each image "
                         "names one photo; remove the duplicates")


def check_model_cameras(model: Path, rec) -> None:
    """ValueError, one line naming the model's file, the image and the field, unless every registered image of ``rec``
    is a camera a camera can be (:func:`curate.core.cameras.check_poses`): its pose (``images.bin``/``.txt``), its
    camera's focal length, principal point, size and distortion (``cameras.bin``/``.txt``); and no two images may
    share a name (each names one photo)."""
    from collections import Counter
    from curate.core.cameras import check_poses
    a = _arrays(rec, warn=False)
    ext = "bin" if (model / "images.bin").is_file() else "txt"
    images, cameras = model / f"images.{ext}", f"cameras.{ext}"
    dup = [n for n, k in Counter(a["names"]).items() if k > 1]
    if dup:
        raise ValueError(f"{images}: {len(dup)} image name(s) appear more than once, e.g. {dup[0]!r}: each image names "
                         "one photo; remove the duplicates")
    fields = {"c2w": "its pose (QW QX QY QZ TX TY TZ)", "centre": "its pose's camera centre",
              **{k: f"{k} of its camera in {cameras}" for k in ("fx", "fy", "cx", "cy")},
              "width": f"WIDTH of its camera in {cameras}", "height": f"HEIGHT of its camera in {cameras}",
              "dist": f"the distortion of its camera in {cameras}", "k1 k2": f"k1 k2 of its camera in {cameras}",
              "p1 p2": f"p1 p2 of its camera in {cameras}"}
    check_poses(a["c2w"], a["fx"], a["fy"], a["cx"], a["cy"], a["width"], a["height"], a["names"], str(images),
                dist=a["dist"], fields=fields)


def read_colmap_model(model: Path, photos: Path | None):
    """A COLMAP model folder as :class:`Poses`: image paths under ``photos`` when given, else the model's own folder's
    file where it has one (else the bare name: a camera without a photo), a name that leaves the folder being a
    ``ValueError`` naming ``images.bin``/``images.txt`` and the image."""
    pycolmap = load_pycolmap()
    check_model_files(Path(model))          # before COLMAP's reader, which fails on these without saying where
    bad = [(f, n) for f, n, q in raw_quaternions(Path(model))
           if not (np.all(np.isfinite(q)) and np.linalg.norm(q) > 1e-6)]
    if bad:   # pycolmap normalises a zero quaternion to the identity: a made-up pose, never a silent one
        raise ValueError(f"{bad[0][0]}: image {bad[0][1]} has a rotation quaternion of zero length or not finite "
                         f"({len(bad)} image(s)); fix or remove it")
    try:
        rec = pycolmap.Reconstruction(model)
    except Exception as e:  # noqa: BLE001 - pycolmap raises its own error types
        said = re.sub(r"\[[\w./-]+:\d+\] Check failed: ", "COLMAP's check of ", str(e)).strip()
        raise ValueError(f"{model}: cannot read the COLMAP model ({said})") from None
    check_model_cameras(Path(model), rec)
    cams, xyz, rgb, err = cameras_from_reconstruction(rec)
    if photos is not None:   # looked up in the photo folder only (curate.sfm.poses.match_photos)
        files = [str((photos / n).resolve()) for n in cams.names]
    else:   # found in the model's own folder, else cameras without a photo; never outside the model's folder
        from curate.core.paths import within_capture
        images = Path(model) / ("images.bin" if (Path(model) / "images.bin").is_file() else "images.txt")
        found = [within_capture(model, n, images, "an image") for n in cams.names]
        files = [str(f.resolve()) if f.is_file() else n for f, n in zip(found, cams.names)]
    return Poses(cams, files, xyz, rgb, err, rec)


def write_model(rec, path: str | Path) -> None:
    """Write ``rec`` as a binary COLMAP model into ``path``, then read its files back to their last byte
    (:func:`check_model_files`): COLMAP's writer says nothing when the disk fills (it left empty cameras.bin and
    images.bin, exit 0). A model cut short is an ``OSError`` (no space left: ENOSPC) naming the folder."""
    import errno
    import shutil
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(path))
    try:
        check_model_files(path)
        for f in ("cameras.bin", "images.bin", "points3D.bin"):
            if not (path / f).is_file():
                raise ValueError(f"{path / f} was not written")
    except ValueError as e:
        free = shutil.disk_usage(path).free
        if free < (1 << 20):
            raise OSError(errno.ENOSPC, "No space left on device", str(path)) from None
        raise OSError(errno.EIO, f"COLMAP wrote an incomplete model ({e})", str(path)) from None


def pycolmap_reconstruction(path: str | Path):
    """The COLMAP model at ``path`` (pycolmap stays inside :mod:`curate.sfm`)."""
    pycolmap = load_pycolmap()
    return pycolmap.Reconstruction(str(path))
