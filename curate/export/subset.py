"""Export the chosen subset of a run as a ready-to-train dataset.

``export_subset(run_dir, chosen_names, out_dir)`` writes, into ``out_dir`` (normally
``RUN/export``):

* ``images/``: the chosen ORIGINAL photos (never the working copies), as symbolic links
  to the originals (``mode="link"``, absolute targets) or copies (``mode="copy"``). A file
  is named after the original (its base name; the path relative to the photo folder with
  ``/`` turned into ``__`` when two originals share a base name). RAW originals are linked
  or copied as they are (``.dng``, ``.cr2``...): most NeRF tools cannot read them; convert
  them first. Originals carrying a non-trivial EXIF orientation are linked as they are too:
  the cameras describe the UPRIGHT image (as curate decoded it), so a tool must apply the
  EXIF orientation (nerfstudio and PIL's ``exif_transpose`` do); a warning is logged.
* ``sparse/0/``: a COLMAP binary model of only the chosen images, in COLMAP's world frame
  (that of ``RUN/sfm/sparse/0``), image names = the names in ``images/`` and cameras
  rescaled to the originals' resolution, so ``out_dir`` is a complete COLMAP dataset
  (Gaussian splatting's ``-s out_dir``, ``ns-process-data``). 3D points are kept when at
  least ``min_track`` (default 2) chosen images observe them, with only those observations.
* ``transforms.json``: the same cameras (nerfstudio / instant-ngp, OpenGL convention, same
  world frame, full-resolution intrinsics), ``file_path`` = ``images/<name>``.
* ``images.txt``: the chosen photos, one per line, in the order chosen, as paths relative
  to the photo folder (for an import: the image names of the imported model/transforms).
* ``export.json``: what was written (mode, per image: camera name, export name, original).

The photo folder is never written: an ``out_dir`` inside it is refused.
"""

from __future__ import annotations

import json
import logging
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

from curate.sfm.io import load_sfm, original_cameras, sfm_dir

logger = logging.getLogger(__name__)

__all__ = ["ExportConfig", "export_subset", "export_names"]

MODES = ("link", "copy")


@dataclass(frozen=True)
class ExportConfig:
    """How the chosen subset is written."""

    mode: str = "link"
    """``link``: symbolic links to the original photos; ``copy``: copies of them."""
    min_track: int = 2
    """A sparse point is kept in ``sparse/0`` when at least this many chosen images observe it."""

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f"export mode must be one of {MODES}, got {self.mode!r}")
        if self.min_track < 1:
            raise ValueError("min_track must be >= 1")


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
    """Folders the export must not be written into: the photo folder of the SfM stage, the originals' folders."""
    roots = {Path(o).resolve().parent for o in originals}
    st = sfm_dir(run_dir) / "stage.json"
    if st.is_file():
        rec = json.loads(st.read_text())
        for k in ("photos",):
            if rec.get(k):
                roots.add(Path(rec[k]).resolve())
    return sorted(roots)


_WRITES = ("images", "sparse", "transforms.json", "images.txt", "export.json")
_MODEL_FILES = tuple(f"{n}.bin" for n in ("cameras", "images", "points3D", "rigs", "frames"))
"""What an export before ``files`` was recorded (curate 0.2) may have written in ``sparse/0`` (binary only: a
``.txt`` model there is the user's, from ``colmap model_converter``)."""


def _sha256(p: Path) -> str:
    import hashlib
    h = hashlib.sha256()
    with open(p, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def check_unchanged(out: str | Path) -> None:
    """``ValueError`` naming the first file of the export in ``out`` that was changed since curate wrote it
    (:func:`_changed`): clearing the export would delete a user's edit. Nothing without a readable
    ``export.json``: there is no record to check against (the run folder's export stage then clears
    ``RUN/export``, an export cut short; :func:`_clear` refuses a folder given as ``--out``)."""
    out = Path(out)
    try:
        changed = _changed(out, json.loads((out / "export.json").read_text()))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return
    if changed:
        raise ValueError(_changed_said(changed, out))


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
    for it in prev.get("images", []):
        p = out / "images" / it["name"]
        if p.is_symlink():
            if os.readlink(p) != it["original"]:
                return str(p)
        elif p.is_file() and f"images/{it['name']}" not in digests:   # a copy of 0.2: against its original
            orig = Path(it["original"])
            if not (orig.is_file() and filecmp.cmp(p, orig, shallow=False)):
                return str(p)
    for rel, digest in digests.items():             # since 0.3: each file written, copies included
        p = out / rel
        if p.is_file() and not p.is_symlink() and _sha256(p) != digest:
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
    written = prev.get("files")
    model = [f for f in written if f.startswith("sparse/0/")] if written else [f"sparse/0/{n}" for n in _MODEL_FILES]
    for f in model:
        (out / f).unlink(missing_ok=True)
    for d in (out / "images", out / "sparse" / "0", out / "sparse"):
        if d.is_dir() and not d.is_symlink() and not any(d.iterdir()):
            d.rmdir()
    for name in ("transforms.json", "images.txt", "export.json"):
        (out / name).unlink(missing_ok=True)


def export_subset(run_dir: str | Path, chosen_names: list[str], out_dir: str | Path | None = None,
                  mode: str = "link", config: ExportConfig | None = None) -> Path:
    """Write the chosen cameras of the run's SfM stage as a dataset in ``out_dir``; returns ``out_dir``.

    Args:
        run_dir: run folder with a finished SfM / import stage (``RUN/sfm``).
        chosen_names: [K] camera names of ``RUN/sfm/cameras.json`` (= ``chosen_names`` of
            ``selection.json``), in the order chosen. Unknown or repeated names: ``ValueError``.
        out_dir: destination (default ``RUN/export``); what an earlier export wrote there is replaced.
        mode: ``link`` (symbolic links to the originals, default) or ``copy``.
        config: overrides ``mode`` when given (``min_track`` lives there).

    Layout of ``out_dir``: see the module docstring.
    """
    cfg = config or ExportConfig(mode=mode)
    run_dir = Path(run_dir).resolve()
    out = Path(out_dir).resolve() if out_dir is not None else run_dir / "export"
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
    originals = [str(Path(recs.get(n, {}).get("original") or paths[i]).resolve()) for n, i in zip(chosen, idx)]
    rels = [recs.get(n, {}).get("rel") or n for n in chosen]
    names = export_names(originals, rels)
    for root in _photo_roots(run_dir, originals):
        if out == root or root in out.parents:
            raise ValueError(f"export folder {out} is inside the photo folder {root}: the photo folder is never written")
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
        dst = img_dir / name
        if cfg.mode == "link":
            os.symlink(src, dst)
        else:
            shutil.copy2(src, dst)
    rotated = [n for n in chosen if int(recs.get(n, {}).get("orientation", 1) or 1) != 1]
    if rotated:
        logger.warning("export: %d original(s) carry an EXIF rotation (%s...): the cameras describe the upright "
                       "image, read them with the EXIF orientation applied", len(rotated), rotated[0])
    raw = [n for n, r in zip(names, chosen) if recs.get(r, {}).get("format") == "raw"]
    if raw:
        logger.warning("export: %d RAW original(s) (%s...) linked as they are: convert them for NeRF tools",
                       len(raw), raw[0])

    from curate.sfm.colmap import write_subset_model  # pycolmap lives there
    sizes = {n: (int(sub.width[k]), int(sub.height[k])) for k, n in enumerate(chosen)}
    model = write_subset_model(sfm_dir(run_dir) / "sparse" / "0", chosen, out / "sparse" / "0",
                               rename=dict(zip(chosen, names)), sizes=sizes, min_track=cfg.min_track)

    from curate.core.transforms_json import write_transforms
    write_transforms(out / "transforms.json", sub, [f"images/{n}" for n in names])
    (out / "images.txt").write_text("".join(r + "\n" for r in rels))
    files = ["transforms.json", "images.txt"] + sorted(f"sparse/0/{p.name}" for p in (out / "sparse" / "0").iterdir()
                                                       if p.is_file())
    if cfg.mode == "copy":   # a copy is checked against what was written, wherever its original is now
        files += [f"images/{n}" for n in names]
    manifest = {"config": asdict(cfg), "run_dir": str(run_dir), "n_images": len(chosen), "model": model,
                "images": [{"camera": c, "name": n, "original": o, "rel": r}
                           for c, n, o, r in zip(chosen, names, originals, rels)],
                "files": {f: _sha256(out / f) for f in files}}
    from curate.core.stage import write_json_atomic
    write_json_atomic(out / "export.json", manifest)      # never half written: it is the record of what to check
    logger.info("export: %d images (%s), %d sparse points -> %s", len(chosen), cfg.mode, model["n_points3D"], out)
    return out
