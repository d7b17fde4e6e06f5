"""One reader of known poses for every command (``run``, ``sfm``, ``select``, ``score``, ``batch``).

A pose source is a transforms.json (nerfstudio / Instant-NGP), the project's own
``cameras.json``, a COLMAP model folder (binary or text, or a folder holding ``sparse/0``)
or a run folder (its ``sfm/cameras.json``), or a folder holding one of them.
:func:`find_pose_source` says which file or folder of a folder holds poses; :func:`read_poses`
reads any of them (every command goes through it); :func:`match_photos` finds each pose's
photo in a photo folder given beside the poses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path


from curate.core.cameras import Cameras
from curate.core.paths import inside, within_capture
from curate.sfm.model import Poses, read_colmap_model


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

    ``photos``: the folder a COLMAP model's (or a cameras.json's) image names are relative to
    (default: :func:`default_photos`; else a cameras.json's names, like a transforms.json's file
    paths, are resolved against its own folder). Raises FileNotFoundError or ValueError with a message naming the file.

    No pose names a file outside its capture: without ``photos``, an image path that leaves the folder it is
    resolved against (``..``, an absolute path elsewhere, a link out) is a ``ValueError`` naming the pose file
    and the entry (:func:`curate.core.paths.within_capture`); with ``photos``, each pose's photo is looked up
    in that folder only (:func:`match_photos`).
    """
    source = Path(source)
    if not source.exists():
        raise FileNotFoundError(f"{source}: no such file or folder")
    if source.is_dir():
        model = _colmap_model(source)
        if model is not None:
            photos = photos if photos is not None else default_photos(source)
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
    except RecursionError:
        raise ValueError(f"{source}: not a pose file: its JSON is nested too deeply to read") from None
    try:
        if isinstance(data, dict) and "convention" in data:
            try:
                cams = Cameras.from_dict(data)
            except ValueError as e:   # a value no camera has: the file, the camera and the field named
                raise ValueError(f"{source}: {e}") from None
            from curate.core.cameras import check_poses
            check_poses(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height, cams.names, str(source),
                        dist=cams.dist)
            # names relative to the photo folder (a run folder's sfm/images), else to the file's own folder
            if photos is not None:   # looked up in the photo folder only (match_photos)
                return Poses(cams, [str((Path(photos) / n).resolve()) if n else n for n in cams.names])
            base = default_photos(source) or source.parent
            return Poses(cams, [str(within_capture(base, n, source, f"camera {k}").resolve()) if n else n
                                for k, n in enumerate(cams.names)])
        from curate.core.transforms_json import read_transforms
        cams, files = read_transforms(source, photos)
        return Poses(cams, files)
    except (KeyError, TypeError, IndexError) as e:
        raise ValueError(f"{source}: not a transforms.json or cameras.json ({type(e).__name__}: {e})") from None


# ------------------------------------------------------------------ files of a pose source
_MODEL_FILES = tuple(f"{n}.{e}" for n in ("cameras", "images", "points3D", "rigs", "frames") for e in ("bin", "txt"))


def pose_files(source: str | Path) -> list[Path]:
    """The files that hold the poses of ``source`` (a file or a folder, see :func:`find_pose_source`):
    the transforms.json or cameras.json itself, or a COLMAP model's ``cameras/images/points3D``
    (``rigs/frames``) files; [] when it holds none. A stage key hashes these, not the photos beside them."""
    source = Path(source)
    if source.is_file():
        return [source]
    model = _colmap_model(source)
    if model is not None:
        return [model / f for f in _MODEL_FILES if (model / f).is_file()]
    found = find_pose_source(source) if source.is_dir() else None
    return pose_files(found) if found is not None else []


def default_photos(source: str | Path) -> Path | None:
    """The photo folder of a pose source given without one, by the usual layouts: a COLMAP model's
    ``images/`` (``SCENE/images`` beside ``SCENE/sparse/0``, or inside the ``SCENE`` folder given),
    a run folder's ``sfm/images`` (the working copies its ``sfm/cameras.json`` names); None otherwise
    (a transforms.json's paths are resolved against its own folder)."""
    source = Path(source)
    if source.is_dir() and _colmap_model(source) is not None:
        model = _colmap_model(source)
        for scene in ((model.parent.parent,) if model.parent.name == "sparse" else ()) + (source,):
            if (scene / "images").is_dir():
                return scene / "images"
        return None
    if source.is_dir():
        found = find_pose_source(source)
        return default_photos(found) if found is not None and found != source else None
    if source.name == "cameras.json" and source.parent.name == "sfm" and (source.parent / "images").is_dir():
        return source.parent / "images"
    return None


# ------------------------------------------------------------------ poses to the photos of a folder
MIN_MATCHED_FRACTION = 0.5
"""With a photo folder and poses: fewer than this share of the poses finding a photo, or of the
folder's photos having a pose, is warned about loudly (the folder is probably not the capture
the poses describe); none at all is an error."""


@dataclass
class PhotoMatch:
    """Which photo of a folder each pose describes (:func:`match_photos`)."""

    files: list[str | None]
    """[N] per pose: the absolute path of its photo, None when the folder has none."""
    how: list[str]
    """[N] per pose: ``path`` (its path relative to the folder), ``name`` (its unique file name) or
    the reason it found no photo."""
    unposed: list[Path]
    """Photos (and videos) of the folder that no pose names."""
    n_photos: int
    """Photos (and videos) in the folder."""

    @property
    def matched(self) -> list[int]:
        """Indices of the poses that found a photo."""
        return [i for i, f in enumerate(self.files) if f is not None]


def _rel_name(name: str, own: str | None, folder: Path) -> str | None:
    """A pose's image as a path relative to ``folder``: its own resolved file when that lies in the
    folder, else its name when the name is relative and does not leave the folder."""
    import os
    if own and Path(own).is_absolute():
        try:
            return Path(own).resolve().relative_to(folder).as_posix()
        except ValueError:
            pass
    if not name or Path(name).is_absolute():
        return None
    rel = os.path.normpath(name).replace("\\", "/")
    return None if rel == "." or rel.startswith("../") or rel == ".." else rel


def _with_ext(p: Path) -> Path | None:
    """``p`` when it is a file; else, for a name without an image extension (Blender-synthetic
    ``r_0``), the file with one."""
    if p.is_file():
        return p
    from curate.core.images import IMAGE_EXTS
    if p.suffix.lower() not in IMAGE_EXTS:
        for ext in sorted(IMAGE_EXTS) + sorted(e.upper() for e in IMAGE_EXTS):
            q = p.with_name(p.name + ext)
            if q.is_file():
                return q
    return None


def match_photos(names: list[str], own: list[str], folder: str | Path, recursive: bool = False,
                 source: str | Path | None = None) -> PhotoMatch:
    """Look each pose's image up in the photo folder ``folder`` (read only).

    A pose's photo is, in this order: its own resolved file (``own``) when that lies inside the
    folder; the file at its name taken relative to the folder (``images/frame_0001.jpg`` under
    ``FOLDER``); else the one photo of the folder with its file name (extension optional, as in
    Blender-synthetic files), provided that no other photo of the folder and no other pose has that
    name. The folder's photos are its image files and videos (sub-folders with ``recursive``);
    those no pose names are listed in ``unposed``. A photo found that is a link leading out of the folder is a
    ``ValueError`` naming ``source`` (the pose file) and the pose: nothing outside the folder is read.

    Args:
        names: [N] the poses' image names as the source writes them.
        own: [N] the source's own resolution of each (absolute where it could be resolved).
    """
    from collections import Counter

    from curate.sfm.ingest import find_images, text_name
    from curate.sfm.video import VIDEO_EXTS
    folder = Path(folder).resolve()
    imgs, other = find_images(folder, recursive)
    odd = [p for p in imgs if not text_name(p)]          # a name that is not UTF-8 is no pose's: listed as left out
    imgs = [p for p in imgs if p.is_file() and text_name(p)]   # a link to nothing (gone, a loop) is no pose's photo
    other = [p for p in other if p.is_file()]
    photos = ([p.resolve() for p in imgs] + [p.resolve() for p in other if p.suffix.lower() in VIDEO_EXTS]
              + [p for p in odd if p.is_file()])
    by_name: dict[str, list[Path]] = {}
    for p in imgs:
        by_name.setdefault(p.name, []).append(p.resolve())
        by_name.setdefault(p.stem, []).append(p.resolve())
    pose_base = Counter(Path(n).name for n in names)
    files: list[str | None] = []
    how: list[str] = []
    taken: set[Path] = set()
    for n, o in zip(names, own):
        rel = _rel_name(n, o, folder)
        p = _with_ext(folder / rel) if rel is not None and inside(folder / rel, folder) else None
        if p is not None and not inside(p, folder):
            within_capture(folder, rel, source or folder, f"the pose of {n!r}")
        if p is not None and p.resolve() not in taken:
            files.append(str(p.resolve()))
            how.append("path")
            taken.add(p.resolve())
            continue
        base = Path(n).name
        cands = by_name.get(base, [])
        if len(cands) == 1 and not inside(cands[0], folder):
            within_capture(folder, base, source or folder, f"the pose of {n!r}")
        if len(cands) == 1 and pose_base[base] == 1 and cands[0] not in taken:
            files.append(str(cands[0]))
            how.append("name")
            taken.add(cands[0])
            continue
        files.append(None)
        if len(cands) > 1:
            how.append(f"{len(cands)} photos of {folder} are named {base}: which one is meant is unclear")
        elif cands and pose_base[base] > 1:
            how.append(f"{pose_base[base]} poses are named {base}: which one the photo {cands[0]} is, is unclear")
        else:
            how.append(f"no photo {rel or n} or named {base} in {folder}")
    unposed = [p for p in photos if p not in taken]
    return PhotoMatch(files, how, unposed, len(photos))
