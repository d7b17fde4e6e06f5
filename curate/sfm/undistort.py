"""The export's model made trainable: undistorted images with PINHOLE cameras, and the model's points.

The reference 3D Gaussian splatting loader (``readColmapCameras``) reads PINHOLE and SIMPLE_PINHOLE cameras only,
and nerfstudio's and 3DGS's own converters undistort for that reason. :func:`undistort_model` runs COLMAP's image
undistorter (``pycolmap.undistort_images``) on an exported subset model; :func:`model_points` reads a model's
points for the PLY that nerfstudio's splatfacto starts from. Part of the SfM package: the only pycolmap user.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from curate.sfm.native import colmap_log, load as load_pycolmap

PINHOLE_MODELS = ("PINHOLE", "SIMPLE_PINHOLE")
"""Camera models every trainer reads as they are."""


def distorted_cameras(sparse_dir: str | Path) -> list[str]:
    """Names of the camera models of the model in ``sparse_dir`` that carry distortion (a model outside
    :data:`PINHOLE_MODELS` with a non-zero distortion parameter), one entry per such camera."""
    pycolmap = load_pycolmap()
    rec = pycolmap.Reconstruction(str(sparse_dir))
    out = []
    for cam in rec.cameras.values():
        if cam.model_name in PINHOLE_MODELS:
            continue
        extra = list(cam.extra_params_idxs()) if hasattr(cam, "extra_params_idxs") else []
        params = np.asarray(cam.params, float)
        if not extra or np.any(params[extra] != 0):
            out.append(cam.model_name)
    return out


def undistort_model(sparse_dir: str | Path, image_dir: str | Path, out_dir: str | Path,
                    log: str | Path | None = None) -> dict[str, tuple[float, float, float, float, int, int]]:
    """Undistort every image of the model in ``sparse_dir`` (its files in ``image_dir``, named as in the model)
    with COLMAP's image undistorter into ``out_dir/images`` and ``out_dir/sparse`` (PINHOLE cameras, the same
    poses and points; the image sizes may change: COLMAP keeps the undistorted image's valid pixels).

    Returns:
        {image name: (fx, fy, cx, cy, width, height)} of the undistorted images.
    """
    pycolmap = load_pycolmap()
    out_dir = Path(out_dir)
    names = [im.name for im in pycolmap.Reconstruction(str(sparse_dir)).images.values()]
    with colmap_log(Path(log) if log else out_dir.parent / "undistort.log"):
        pycolmap.undistort_images(str(out_dir), str(sparse_dir), str(image_dir), image_names=names,
                                  output_type="COLMAP", num_threads=1)
    for extra in ("stereo", "run-colmap-geometric.sh", "run-colmap-photometric.sh"):   # for dense MVS only
        p = out_dir / extra
        if p.is_dir():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
    rec = pycolmap.Reconstruction(str(out_dir / "sparse"))
    out = {}
    for im in rec.images.values():
        cam = rec.camera(im.camera_id)
        if cam.model_name != "PINHOLE":
            raise RuntimeError(f"COLMAP's undistorter left a {cam.model_name} camera for {im.name}")
        fx, fy, cx, cy = (float(v) for v in cam.params)
        out[im.name] = (fx, fy, cx, cy, int(cam.width), int(cam.height))
    missing = sorted(set(names) - set(out))
    if missing:
        raise RuntimeError(f"COLMAP's undistorter dropped {len(missing)} image(s): {missing[:3]}")
    return out


def model_points(sparse_dir: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(xyz [P, 3] float64, rgb [P, 3] uint8) of the 3D points of the model in ``sparse_dir``."""
    pycolmap = load_pycolmap()
    rec = pycolmap.Reconstruction(str(sparse_dir))
    pts = list(rec.points3D.values())
    if not pts:
        return np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    return (np.array([p.xyz for p in pts], np.float64).reshape(-1, 3),
            np.array([p.color for p in pts], np.uint8).reshape(-1, 3))
