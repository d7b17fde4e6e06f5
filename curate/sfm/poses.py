"""One reader of known poses for every command (``run``, ``sfm``, ``select``, ``score``, ``batch``).

A pose source is a transforms.json (nerfstudio / Instant-NGP), the project's own
``cameras.json``, a COLMAP model folder (binary or text, or a folder holding ``sparse/0``)
or a run folder (its ``sfm/cameras.json``). :func:`find_pose_source` says which file or
folder of a folder holds poses; :func:`read_poses` reads any of them.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from curate.core.cameras import Cameras


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


def _colmap_model(path: Path) -> Path | None:
    for model in (path, path / "sparse" / "0"):
        if any((model / f).is_file() for f in ("cameras.bin", "cameras.txt")):
            return model
    return None


def find_pose_source(folder: str | Path) -> Path | None:
    """The pose source inside ``folder`` (or ``folder`` itself when it is a COLMAP model): its
    transforms.json, else its COLMAP model (``sparse/0``), else ``cameras.json``, else a run
    folder's ``sfm/cameras.json``; None when it holds no poses."""
    folder = Path(folder)
    if (folder / "transforms.json").is_file():
        return folder / "transforms.json"
    if _colmap_model(folder) is not None:
        return folder
    for name in ("cameras.json", "sfm/cameras.json"):
        if (folder / name).is_file():
            return folder / name
    return None


def read_poses(source: str | Path, photos: str | Path | None = None) -> Poses:
    """The cameras of a pose source (a file or a folder, see :func:`find_pose_source`), without writing anything.

    ``photos``: the folder a COLMAP model's image names are relative to (a transforms.json's
    file paths are resolved against its own folder). Raises FileNotFoundError or ValueError
    with a message naming the file.
    """
    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: no such file or folder")
    if source.is_dir():
        model = _colmap_model(source)
        if model is not None:
            from curate.sfm.colmap import read_colmap_model
            return read_colmap_model(model, Path(photos) if photos is not None else None)
        found = find_pose_source(source)
        if found is None:
            raise FileNotFoundError(f"{source}: a folder without a COLMAP model, transforms.json or cameras.json")
        return read_poses(found, photos)
    try:
        data = json.loads(source.read_text())
    except (OSError, UnicodeDecodeError) as e:
        raise ValueError(f"{source}: not a readable file ({e})") from None
    except json.JSONDecodeError as e:
        raise ValueError(f"{source}: not valid JSON (line {e.lineno}, column {e.colno}: {e.msg})") from None
    try:
        if isinstance(data, dict) and "convention" in data:
            cams = Cameras.from_dict(data)
            from curate.core.cameras import check_poses
            check_poses(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height, cams.names, str(source))
            return Poses(cams, list(cams.names))
        from curate.core.transforms_json import read_transforms
        cams, files = read_transforms(source)
        return Poses(cams, files)
    except (KeyError, TypeError, IndexError) as e:
        raise ValueError(f"{source}: not a transforms.json or cameras.json ({type(e).__name__}: {e})") from None
