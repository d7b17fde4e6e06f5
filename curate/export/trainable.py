"""What makes an export train as it is: the point cloud as a PLY, downscaled images, and the next step's commands.

* :func:`write_ply`: the model's points as a binary PLY (``x y z`` float, ``red green blue`` uchar), the file
  nerfstudio's ``transforms.json`` names in ``ply_file_path`` (splatfacto starts from it, not from random points);
* :func:`downscale_images`: ``images_F/`` beside ``images/``, each image shrunk by ``F`` (its size floored, as
  ``ns-process-data`` writes them), for nerfstudio's ``--downscale-factor F``;
* :func:`train_commands`: the command lines that train on the export (nerfstudio, 3DGS, gsplat).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

PLY_NAME = "sparse_pc.ply"
"""The point cloud's file name in the export (the name ``ns-process-data`` gives it)."""


def write_ply(path: str | Path, xyz: np.ndarray, rgb: np.ndarray) -> Path:
    """Write points ``xyz`` [P, 3] with colours ``rgb`` [P, 3] uint8 as a binary little-endian PLY."""
    xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
    rgb = np.asarray(rgb, np.uint8).reshape(-1, 3)
    if len(xyz) != len(rgb):
        raise ValueError(f"{len(xyz)} points and {len(rgb)} colours")
    if not np.isfinite(xyz).all():
        raise ValueError("a point with a non-finite coordinate")
    rec = np.empty(len(xyz), dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                    ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for i, k in enumerate("xyz"):
        rec[k] = xyz[:, i]
    for i, k in enumerate(("red", "green", "blue")):
        rec[k] = rgb[:, i]
    head = ("ply\nformat binary_little_endian 1.0\n"
            f"element vertex {len(xyz)}\n"
            "property float x\nproperty float y\nproperty float z\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n")
    path = Path(path)
    with open(path, "wb") as f:
        f.write(head.encode("ascii"))
        f.write(rec.tobytes())
    return path


def downscale_images(image_dir: Path, names: list[str], factor: int, out_dir: Path) -> list[str]:
    """Write each of ``names`` in ``image_dir`` shrunk by ``factor`` (size floored, Lanczos) into ``out_dir``
    under the same name and format; returns the names written. Pixels are taken as stored and a JPEG's EXIF is
    kept, so a copy carries the same orientation tag as the image it shrinks."""
    from PIL import Image
    out_dir.mkdir(parents=True, exist_ok=True)
    for n in names:
        with Image.open(image_dir / n) as im:
            w, h = max(1, im.width // factor), max(1, im.height // factor)
            small = im.resize((w, h), Image.Resampling.LANCZOS)
            kw = {"quality": 95, "exif": im.info.get("exif", b"")} if (im.format or "").upper() == "JPEG" else {}
            small.save(out_dir / n, format=im.format, **kw)
    return list(names)


def train_commands(export_dir: str | Path) -> list[tuple[str, str]]:
    """(tool, command line) pairs that train on the export in ``export_dir``."""
    import shlex
    e = shlex.quote(str(export_dir))
    return [("nerfstudio, Gaussian splatting", f"ns-train splatfacto --data {e}"),
            ("nerfstudio, NeRF", f"ns-train nerfacto --data {e}"),
            ("3D Gaussian splatting (reference code)", f"python train.py -s {e}"),
            ("gsplat", f"python examples/simple_trainer.py default --data_dir {e} --data_factor 1")]
