"""Export the chosen subset of a run as a dataset the trainers read as it is.

``export_subset(run_dir, chosen_names, out_dir, config=ExportConfig())`` writes, into ``out_dir`` (normally
``RUN/export``):

* ``images/``: the chosen photos. Without lens distortion (or ``undistort='off'``): the ORIGINAL photos (never
  the working copies) as hard links (``mode='hardlink'``, the default; copies where the file system allows no
  hard link), copies (``'copy'``) or symbolic links (``'link'``, absolute targets). With distortion (a phone
  video's SIMPLE_RADIAL) and ``undistort='auto'``: the originals undistorted by COLMAP's undistorter
  (:func:`curate.sfm.undistort.undistort_model`), new files, with PINHOLE cameras (3D Gaussian splatting's loader
  reads no other); ``keep_distorted`` keeps the originals and their model in ``distorted/``. A file is named after
  the original (its base name; the path relative to the photo folder with ``/`` turned into ``__`` when two
  originals share a base name). RAW originals are exported as they are (convert them for NeRF tools; no
  undistortion). Originals carrying an EXIF orientation are exported as they are when not undistorted (the
  cameras describe the upright image: a tool must apply the orientation, as nerfstudio and PIL's
  ``exif_transpose`` do; a warning is logged), and upright when undistorted.
* ``sparse/0/``: a COLMAP binary model of only the chosen images, in COLMAP's world frame (that of
  ``RUN/sfm/sparse/0``), image names = the names in ``images/``, cameras at the exported images' resolution:
  ``out_dir`` is a complete COLMAP dataset (3DGS's ``-s out_dir``, gsplat's ``--data_dir``). 3D points are kept
  when at least ``min_track`` (default 2) chosen images observe them, with only those observations.
* ``sparse_pc.ply``: those points (:func:`curate.export.trainable.write_ply`), named by ``transforms.json``'s
  ``ply_file_path`` (nerfstudio's splatfacto starts from it).
* ``transforms.json``: the same cameras (nerfstudio / instant-ngp, OpenGL convention, same world frame),
  ``file_path`` = ``images/<name>``.
* ``images_2/``, ``images_4/``, ``images_8/``: with ``downscale``, the images shrunk by each factor.
* ``images.txt``: the chosen photos, one per line, in the order chosen, as paths relative to the photo folder
  (for an import: the image names of the imported model/transforms).
* ``export.json``: what was written (config, per image: camera name, export name, original; the checksum of
  every file written except symbolic links).

The photo folder is never written: an ``out_dir`` inside it is refused. A re-export removes only what the
previous one wrote, and nothing when one of those files was changed since (a user's edit is theirs).
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from dataclasses import asdict
from pathlib import Path

from curate.core.paths import RunPaths
from curate.core.runfolder import sha256_file
from curate.core.stage import read_stage, write_json_atomic
from curate.export.config import ExportConfig
from curate.export.trainable import PLY_NAME
from curate.sfm.io import known_original, load_sfm, original_cameras, sfm_dir

logger = logging.getLogger(__name__)

__all__ = ["ExportConfig", "export_subset", "export_names"]


def export_names(originals: list[str], rels: list[str]) -> list[str]:
    """File names in ``images/`` for the originals: base names, unique.

    A base name shared by several originals becomes the relative path with ``/`` -> ``__``
    (then, if still not unique, prefixed by its position ``0007_``).
    """
    base = [Path(o).name for o in originals]
    count: dict[str, int] = {}
    for b in base:
        count[b] = count.get(b, 0) + 1
    out = [b if count[b] == 1 else r.replace("/", "__").replace("\\", "__") for b, r in zip(base, rels)]
    if len(set(out)) != len(out):
        out = [f"{i:04d}_{n}" for i, n in enumerate(out)]
    return out


def _photo_roots(run_dir: Path, originals: list[str]) -> list[Path]:
    """Folders the export must not be written into: the photo folder of the SfM stage, the originals' folders. The
    run folder's claim (:func:`curate.core.runfolder.claimed`) already keeps it out of the inputs it was given; the
    folders of the photos a pose file names are known only here."""
    roots = {Path(o).resolve().parent for o in originals}
    rec = read_stage(sfm_dir(run_dir))
    if rec is not None:
        for k in ("photos",):
            if rec.get(k):
                roots.add(Path(rec[k]).resolve())
    return sorted(roots)


_WRITES = ("images", "sparse", "transforms.json", "images.txt", "export.json", PLY_NAME, "distorted", "images_2",
           "images_4", "images_8")
_DIRS = ("images", "images_2", "images_4", "images_8", "sparse/0", "sparse", "distorted/images", "distorted/sparse/0",
         "distorted/sparse", "distorted")
"""Folders an export may have made, deepest first: removed by a re-export when left empty."""
_MODEL_FILES = tuple(f"{n}.bin" for n in ("cameras", "images", "points3D", "rigs", "frames"))
"""What an export writes in ``sparse/0`` (binary only: a ``.txt`` model there is the user's, from ``colmap
model_converter``); all an export of curate 0.2, before ``files`` was recorded, may have written there."""


def _changed_said(path: str, out: Path) -> str:
    return (f"{path} was changed since curate exported it: curate does not remove it; move it out of {out} (or "
            "keep the export as it is), then run again")


def _changed(out: Path, prev: dict) -> str | None:
    """The first file an earlier export wrote (per its ``export.json`` ``prev``) that is no longer what it wrote:
    an image that is not the link to its original any more (an image editor's save replaces a link by a file),
    or a file whose checksum changed (``files``, recorded since curate 0.3, copied images included; a copy of
    an earlier export is compared with its original)."""
    import filecmp
    digests = prev.get("files") or {}
    if not isinstance(digests, dict):
        raise ValueError("files is not a mapping")
    for it in prev.get("images", []):
        p = out / "images" / it["name"]
        if p.is_symlink():
            if os.readlink(p) != it["original"]:
                return str(p)
        elif p.is_file() and f"images/{it['name']}" not in digests:   # a copy of 0.2: against its original
            orig = Path(it["original"])
            if not (orig.is_file() and filecmp.cmp(p, orig, shallow=False)):
                return str(p)
    kept = set(prev.get("distorted", []))
    for it in (it for it in prev.get("images", []) if it["name"] in kept):   # originals kept beside undistorted
        p = out / "distorted" / "images" / it["name"]
        if p.is_symlink():
            if os.readlink(p) != it["original"]:
                return str(p)
        elif p.is_file() and f"distorted/images/{it['name']}" not in digests:   # a file where a link was
            return str(p)
    from curate.core.runfolder import is_changed
    for rel, digest in digests.items():             # since 0.3: each file written, copies included (an unreadable
        p = out / rel                               # one counts as changed: curate cannot prove it is its own)
        if os.path.lexists(p) and is_changed(p, digest):
            return str(p)
    return None


def _clear(out: Path) -> None:
    """Remove what an earlier export wrote, as its ``export.json`` lists it (links are removed,
    never their targets); never anything else, and nothing at all when one of those files was changed since
    (``ValueError`` naming it: a user's edit is theirs).

    Without an ``export.json`` (no earlier export) a folder already holding one of the names an
    export writes (``images``, ``sparse``, ``transforms.json``, ``images.txt``) is refused
    (``ValueError``): those are the user's. After clearing, a folder that still holds
    foreign files keeps them (an ``images/`` with the user's photos is refused later only if
    a name clashes).
    """
    man = out / "export.json"
    if not man.is_file():
        clash = [n for n in _WRITES if (out / n).exists() or (out / n).is_symlink()]
        if clash:
            raise ValueError(f"export folder {out} already holds {clash[0]}, not written by a curate export: "
                             "choose an empty folder")
        return
    try:
        prev = json.loads(man.read_text())
        names = [it["name"] for it in prev.get("images", [])]
        changed = _changed(out, prev)
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        raise ValueError(f"{man}: not an export record of curate; choose an empty folder") from None
    if changed:   # a user's edit is theirs: nothing is removed
        raise ValueError(_changed_said(changed, out))
    for n in names:
        p = out / "images" / n
        if p.is_symlink() or p.is_file():
            p.unlink()
    for n in prev.get("distorted", []):          # the originals kept beside an undistorted export
        p = out / "distorted" / "images" / n
        if p.is_symlink() or p.is_file():
            p.unlink()
    written = prev.get("files")
    listed = list(written) if written else [f"sparse/0/{n}" for n in _MODEL_FILES]
    for f in listed:
        if ".." not in Path(f).parts and not Path(f).is_absolute():      # a record names files inside the export
            (out / f).unlink(missing_ok=True)
    for rel in _DIRS:
        d = out / rel
        if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
            d.rmdir()
    for name in ("transforms.json", "images.txt", "export.json"):
        (out / name).unlink(missing_ok=True)


def _place(src: str, dst: Path, mode: str) -> None:
    """Put the original ``src`` at ``dst``: a hard link (a copy where the file system refuses one), a copy, or a
    symbolic link."""
    if mode == "link":
        os.symlink(src, dst)
        return
    if mode == "hardlink":
        try:
            os.link(src, dst)
            return
        except OSError:          # another file system, or one without hard links: a copy
            pass
    shutil.copy2(src, dst)


def export_subset(run_dir: str | Path, chosen_names: list[str], out_dir: str | Path | None = None,
                  mode: str = "hardlink", config: ExportConfig | None = None) -> Path:
    """Write the chosen cameras of the run's SfM stage as a dataset in ``out_dir``; returns ``out_dir``.

    Args:
        run_dir: run folder with a finished SfM / import stage (``RUN/sfm``).
        chosen_names: [K] camera names of ``RUN/sfm/cameras.json`` (= ``chosen_names`` of
            ``selection.json``), in the order chosen. Unknown or repeated names: ``ValueError``.
        out_dir: destination (default ``RUN/export``); what an earlier export wrote there is replaced.
        mode: ``hardlink`` (default), ``copy`` or ``link``, when ``config`` is not given.
        config: the export's options (:class:`curate.export.config.ExportConfig`).

    Layout of ``out_dir``: see the module docstring.
    """
    cfg = config or ExportConfig(mode=mode)
    run_dir = Path(run_dir).resolve()
    out = Path(out_dir).resolve() if out_dir is not None else RunPaths(run_dir).export
    res = load_sfm(run_dir)
    cams = res.cameras
    index = {n: i for i, n in enumerate(cams.names)}
    chosen = list(chosen_names)
    unknown = [n for n in chosen if n not in index]
    if unknown:
        raise ValueError(f"{len(unknown)} chosen name(s) are not registered cameras of {sfm_dir(run_dir)}: "
                         f"{unknown[:5]}")
    if len(set(chosen)) != len(chosen):
        dup = sorted({n for n in chosen if chosen.count(n) > 1})
        raise ValueError(f"chosen names repeated: {dup[:5]}")
    if not chosen:
        raise ValueError("nothing to export: no chosen names")

    full, paths = original_cameras(cams, res.records)
    idx = [index[n] for n in chosen]
    sub = full[idx]
    recs = {r.get("working") or r.get("rel"): r for r in res.records.get("photos", [])}
    # (original_cameras gives the name, not the path, for an import stage: take it from the record)
    originals = [str(Path(known_original(recs.get(n, {}).get("original") or paths[i], run_dir)).resolve())
                 for n, i in zip(chosen, idx)]
    rels = [recs.get(n, {}).get("rel") or n for n in chosen]
    names = export_names(originals, rels)
    for root in _photo_roots(run_dir, originals):
        if out == root or root in out.parents:
            raise ValueError(f"export folder {out} is inside the photo folder {root}: "
                             "the photo folder is never written")
    missing = [o for o in originals if not Path(o).is_file()]
    if missing:
        raise FileNotFoundError(f"{len(missing)} original photo(s) not found: {missing[:3]}")

    out.mkdir(parents=True, exist_ok=True)
    _clear(out)
    img_dir = out / "images"
    img_dir.mkdir(exist_ok=True)
    clash = [n for n in names if (img_dir / n).exists() or (img_dir / n).is_symlink()]
    if clash:
        raise ValueError(f"{img_dir / clash[0]} exists and was not written by a curate export: choose an empty folder")
    for src, name in zip(originals, names):
        _place(src, img_dir / name, cfg.mode)
    rotated = {n for n in chosen if int(recs.get(n, {}).get("orientation", 1) or 1) != 1}
    raw = [n for n, r in zip(names, chosen) if recs.get(r, {}).get("format") == "raw"]

    from curate.sfm.subset_model import write_subset_model  # pycolmap lives there
    sizes = {n: (int(sub.width[k]), int(sub.height[k])) for k, n in enumerate(chosen)}
    model = write_subset_model(sfm_dir(run_dir) / "sparse" / "0", chosen, out / "sparse" / "0",
                               rename=dict(zip(chosen, names)), sizes=sizes, min_track=cfg.min_track)
    undistorted = False
    if cfg.undistort == "auto":
        sub, undistorted = _undistort(out, sub, names, [n in rotated for n in chosen], originals, raw, cfg)
    if rotated and not undistorted:
        logger.warning("export: %d original(s) carry an EXIF rotation (%s...): the cameras describe the upright "
                       "image, read them with the EXIF orientation applied", len(rotated), sorted(rotated)[0])
    if raw:
        logger.warning("export: %d RAW original(s) (%s...) exported as they are: convert them for NeRF tools",
                       len(raw), raw[0])

    from curate.core.transforms_json import write_transforms
    from curate.export.trainable import downscale_images, write_ply
    from curate.sfm.undistort import model_points
    xyz, rgb = model_points(out / "sparse" / "0")
    extra = {}
    if len(xyz):
        write_ply(out / PLY_NAME, xyz, rgb)
        extra["ply_file_path"] = PLY_NAME
    write_transforms(out / "transforms.json", sub, [f"images/{n}" for n in names], extra=extra)
    (out / "images.txt").write_text("".join(r + "\n" for r in rels))
    files = ["transforms.json", "images.txt"] + ([PLY_NAME] if len(xyz) else [])
    # the model's files this export wrote (a text model the user converted beside them, or left there, is theirs)
    files += [f"sparse/0/{n}" for n in _MODEL_FILES if (out / "sparse" / "0" / n).is_file()]
    for f in cfg.downscale:
        files += [f"images_{f}/{n}" for n in downscale_images(img_dir, names, f, out / f"images_{f}")]
    if cfg.mode != "link" or undistorted:   # a file is checked against what was written, wherever its original is
        files += [f"images/{n}" for n in names]
    if undistorted and cfg.keep_distorted:
        files += [f"distorted/sparse/0/{n}" for n in _MODEL_FILES if (out / "distorted" / "sparse" / "0" / n).is_file()]
        if cfg.mode != "link":
            files += [f"distorted/images/{n}" for n in names]
    model.update({"undistorted": undistorted, "camera_model": "PINHOLE" if undistorted else
                  ("OPENCV" if (sub.dist != 0).any() else "PINHOLE")})
    manifest = {"config": asdict(cfg), "run_dir": str(run_dir), "n_images": len(chosen), "model": model,
                "images": [{"camera": c, "name": n, "original": o, "rel": r}
                           for c, n, o, r in zip(chosen, names, originals, rels)],
                "distorted": names if undistorted and cfg.keep_distorted else [],
                "files": {f: sha256_file(out / f) for f in files}}
    write_json_atomic(out / "export.json", manifest)      # never half written: it is the record of what to check
    logger.info("export: %d images (%s%s), %d sparse points -> %s", len(chosen), cfg.mode,
                ", undistorted" if undistorted else "", model["n_points3D"], out)
    return out


def _undistort(out: Path, sub, names: list[str], rotated: list[bool], originals: list[str], raw: list[str],
               cfg: ExportConfig):
    """Undistort the export in ``out`` in place when a camera of its model has distortion: (cameras of the
    undistorted images, True), else (``sub``, False). The placed originals are removed (or moved to
    ``distorted/images`` with ``keep_distorted``), and the undistorted images and model take their place."""
    from curate.sfm.undistort import distorted_cameras, undistort_model
    if not distorted_cameras(out / "sparse" / "0"):
        return sub, False
    if raw:
        logger.warning("export: RAW originals are not undistorted: their distorted cameras are exported as they are")
        return sub, False
    import tempfile
    tmp = Path(tempfile.mkdtemp(prefix=".curate-undistort-", dir=out))   # its own, never a folder found there
    src = tmp / "src"
    src.mkdir()
    for name, rot, orig in zip(names, rotated, originals):
        if rot:            # COLMAP reads the pixels as stored: an EXIF rotation is applied first
            from PIL import Image
            from curate.core.images import read_image
            Image.fromarray(read_image(orig)[0]).save(src / name, quality=95)
        else:
            os.symlink(out / "images" / name, src / name)
    intr = undistort_model(out / "sparse" / "0", src, tmp / "out", log=tmp / "undistort.log")
    # file by file: only what this export wrote moves or goes (a folder may hold the user's files too)
    model = [out / "sparse" / "0" / f for f in _MODEL_FILES if (out / "sparse" / "0" / f).is_file()]
    if cfg.keep_distorted:
        kept_img, kept_model = out / "distorted" / "images", out / "distorted" / "sparse" / "0"
        clash = [p for p in [kept_img / n for n in names] + [kept_model / m.name for m in model]
                 if p.exists() or p.is_symlink()]
        if clash:
            shutil.rmtree(tmp)
            raise ValueError(f"{clash[0]} exists and was not written by a curate export: choose an empty folder")
        kept_img.mkdir(parents=True, exist_ok=True)
        kept_model.mkdir(parents=True, exist_ok=True)
        for n in names:
            os.replace(out / "images" / n, kept_img / n)
        for m in model:
            os.replace(m, kept_model / m.name)
    else:
        for n in names:
            (out / "images" / n).unlink()
        for m in model:
            m.unlink()
    for n in names:
        os.replace(tmp / "out" / "images" / n, out / "images" / n)
    for m in (tmp / "out" / "sparse").iterdir():
        os.replace(m, out / "sparse" / "0" / m.name)
    shutil.rmtree(tmp)
    from curate.core.cameras import Cameras
    k = [intr[n] for n in names]
    cams = Cameras(sub.c2w, [v[0] for v in k], [v[1] for v in k], [v[2] for v in k], [v[3] for v in k],
                   [v[4] for v in k], [v[5] for v in k], names=sub.names)
    return cams, True
