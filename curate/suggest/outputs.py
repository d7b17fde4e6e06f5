"""The suggestions in the formats tools read: NeRF ``transforms.json`` and COLMAP text
(``images.txt``, ``cameras.txt``).

In the world frame of ``RUN/sfm/cameras.json`` (COLMAP's frame after SfM, the poses' frame after an import).
The photos do not exist yet: each pose is named ``suggest_01.jpg``, ``suggest_02.jpg``...
in the order placed, so that a tool driving a camera (a robot, a rendering script) can take them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras, c2w_from_colmap, colmap_from_c2w


def suggestion_names(k: int) -> list[str]:
    """``suggest_01.jpg`` ... for ``k`` poses."""
    width = max(2, len(str(k)))
    return [f"suggest_{i + 1:0{width}d}.jpg" for i in range(k)]


def write_colmap_text(folder: Path, cams: Cameras, names: list[str]) -> tuple[Path, Path]:
    """Write ``cameras.txt`` (one PINHOLE camera per distinct intrinsics) and ``images.txt`` (one pose per camera,
    no 2-D points) into ``folder``; returns their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    intr = [(float(cams.fx[i]), float(cams.fy[i]), float(cams.cx[i]), float(cams.cy[i]), int(cams.width[i]),
             int(cams.height[i])) for i in range(len(cams))]
    ids: dict[tuple, int] = {}
    for t in intr:
        ids.setdefault(t, len(ids) + 1)
    lines = ["# Camera list with one line of data per camera:", "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
             f"# Number of cameras: {len(ids)}"]
    for (fx, fy, cx, cy, w, h), cid in ids.items():
        lines.append(f"{cid} PINHOLE {w} {h} {fx!r} {fy!r} {cx!r} {cy!r}")
    cam_txt = folder / "cameras.txt"
    cam_txt.write_text("\n".join(lines) + "\n")
    q, t = colmap_from_c2w(cams.c2w) if len(cams) else (np.zeros((0, 4)), np.zeros((0, 3)))
    lines = ["# Image list with two lines of data per image:",
             "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
             "#   POINTS2D[] as (X, Y, POINT3D_ID)", f"# Number of images: {len(cams)}, mean observations per image: 0"]
    for i in range(len(cams)):
        lines.append(" ".join([str(i + 1), *(repr(float(v)) for v in q[i]), *(repr(float(v)) for v in t[i]),
                               str(ids[intr[i]]), names[i]]))
        lines.append("")
    img_txt = folder / "images.txt"
    img_txt.write_text("\n".join(lines) + "\n")
    return cam_txt, img_txt


def read_images_txt(path: Path) -> tuple[list[str], np.ndarray, list[int]]:
    """(names, OpenCV camera-to-world [N, 4, 4], camera ids) of a COLMAP ``images.txt``; ValueError naming the
    file and line on a malformed image line."""
    from curate.sfm.io import images_txt_rows
    rows = images_txt_rows(path)
    q = np.array([r[1] for r in rows]).reshape(-1, 4)
    t = np.array([r[2] for r in rows]).reshape(-1, 3)
    c2w = c2w_from_colmap(q, t) if rows else np.zeros((0, 4, 4))
    return [r[0] for r in rows], c2w, [r[3] for r in rows]


def write_transforms_json(path: Path, cams: Cameras, names: list[str]) -> Path:
    """The poses as a nerfstudio / instant-ngp ``transforms.json`` (OpenGL convention, file_path = ``names``)."""
    from curate.core.transforms_json import write_transforms
    return write_transforms(path, cams, names, extra={"curate_note": "suggested poses: no photo taken yet"})
