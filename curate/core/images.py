"""Photos: the record of each input file (``RUN/sfm/images.json``), and decoding, the one way of every path
(SfM ingest, pose imports, the field's loader, the export's copies): upright (EXIF orientation applied),
[H, W, 3] uint8 whatever the mode (16-bit, grey, CMYK, alpha, float), RAW through rawpy, and why a file cannot
be used, in words."""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

PIL_EXTS = {".jpg", ".jpeg", ".png", ".tif", ".tiff"}
RAW_EXTS = {".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".pef", ".srw", ".kdc"}
IMAGE_EXTS = PIL_EXTS | RAW_EXTS

# EXIF tags
_MAKE, _MODEL, _ORIENTATION = 271, 272, 274
_EXIF_IFD, _GPS_IFD = 0x8769, 0x8825
_FOCAL, _FOCAL35 = 37386, 41989


@dataclass
class PhotoRecord:
    """One input file and what ingest made of it (JSON-ready through ``vars``)."""

    original: str                      # absolute path of the input file
    rel: str                           # path relative to the input folder
    status: str = "kept"               # "kept" | "skipped" (later stages may set "dropped")
    reason: str = ""                   # why skipped / dropped
    working: str = ""                  # working-copy file name (in the working folder)
    orig_width: int = 0                # decoded, oriented size of the original
    orig_height: int = 0
    width: int = 0                     # size of the working copy
    height: int = 0
    scale_x: float = 1.0               # width / orig_width
    scale_y: float = 1.0               # height / orig_height
    format: str = ""                   # "jpeg" | "png" | "tiff" | "raw"
    orientation: int = 1               # EXIF orientation tag of the original (1 = upright)
    make: str = ""
    model: str = ""
    focal_mm: float | None = None      # EXIF FocalLength
    focal_35mm: float | None = None    # EXIF FocalLengthIn35mmFilm
    has_gps: bool = False
    extra: dict = field(default_factory=dict)  # quality metrics, registration, ... (filled later)


def _ratio(v) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return f if np.isfinite(f) and f > 0 else None


def _exif_info(im) -> dict:
    """Make, model, focal length (mm, 35 mm equivalent), GPS presence, orientation from a PIL image."""
    out: dict = {}
    try:
        exif = im.getexif()
    except Exception:  # noqa: BLE001 - broken EXIF must not stop ingest
        return out
    out["make"] = str(exif.get(_MAKE, "") or "").strip("\x00 ").strip()
    out["model"] = str(exif.get(_MODEL, "") or "").strip("\x00 ").strip()
    out["orientation"] = int(exif.get(_ORIENTATION, 1) or 1)
    try:
        ifd = exif.get_ifd(_EXIF_IFD)
        out["focal_mm"] = _ratio(ifd.get(_FOCAL))
        out["focal_35mm"] = _ratio(ifd.get(_FOCAL35))
    except Exception:  # noqa: BLE001
        pass
    try:
        gps = exif.get_ifd(_GPS_IFD)
        out["has_gps"] = bool(gps.get(2)) and bool(gps.get(4))  # GPSLatitude and GPSLongitude
    except Exception:  # noqa: BLE001
        pass
    return out


def _to_rgb8(im) -> np.ndarray:
    """PIL image of any mode -> [H, W, 3] uint8."""
    if im.mode in ("I;16", "I;16B", "I;16L", "I"):
        a = np.asarray(im).astype(np.float64)
        top = 65535.0 if a.max() > 255 else 255.0
        a = np.clip(a / top * 255.0 + 0.5, 0, 255).astype(np.uint8)
        return np.repeat(a[..., None], 3, axis=2)
    if im.mode == "F":
        a = np.asarray(im)
        a = np.clip(a * (255.0 if a.max() <= 1.0 else 1.0) + 0.5, 0, 255).astype(np.uint8)
        return np.repeat(a[..., None], 3, axis=2)
    return np.asarray(im.convert("RGB"))


def decode_upright(im, size: tuple[int, int] | None = None) -> np.ndarray:
    """A PIL image -> [H, W, 3] uint8, upright (EXIF orientation applied), whatever its mode
    (16-bit, grayscale, CMYK, alpha, float). ``size`` (width, height of the upright image): a
    JPEG is decoded at the smallest scale that is still at least that large (fast), then
    resized to it. The one decoder of every path (SfM ingest, pose imports, the field's loader)."""
    from PIL import Image, ImageOps
    if size is not None and im.format == "JPEG":
        o = im.getexif().get(0x0112, 1)
        w, h = (size[1], size[0]) if o in (5, 6, 7, 8) else size
        im.draft("RGB", (int(w), int(h)))
    rgb = _to_rgb8(ImageOps.exif_transpose(im))
    if size is not None and (rgb.shape[1], rgb.shape[0]) != tuple(size):
        rgb = np.asarray(Image.fromarray(rgb).resize(tuple(int(v) for v in size), Image.LANCZOS))
    return rgb


def broken_said(path: Path) -> str:
    """Why ``path`` is not a file, for the list of skipped files: missing, a link whose target is gone, a link
    loop."""
    import errno
    if not path.is_symlink():
        return "missing file"
    try:
        path.stat()
    except OSError as e:
        if e.errno == errno.ELOOP:
            return "missing file (a link that leads back to itself: a link loop)"
    return f"missing file (a link whose target is gone: {os.readlink(path)})"


def probe_image(path: str | Path) -> tuple[int, int]:
    """(width, height) of a photo as curate sees it (upright), after checking that it decodes
    whole (at a reduced scale for a JPEG: fast). ValueError with the reason otherwise: missing
    (or a dangling link), empty, truncated, not an image."""
    from PIL import Image
    path = Path(path)
    if not path.is_file():
        raise ValueError(broken_said(path))
    if path.suffix.lower() in RAW_EXTS:
        rgb, _ = read_image(path)
        return int(rgb.shape[1]), int(rgb.shape[0])
    if path.stat().st_size == 0:
        raise ValueError("empty file (0 bytes)")
    try:
        with Image.open(path) as im:
            o = im.getexif().get(0x0112, 1)
            w, h = im.size
            if im.format == "JPEG":
                im.draft("RGB", (max(1, w // 8), max(1, h // 8)))
            im.load()  # raises on truncated data
    except Exception as e:  # noqa: BLE001 - UnidentifiedImageError, truncated, decoder errors
        raise ValueError(f"cannot decode: {type(e).__name__}: {e}") from None
    return (h, w) if o in (5, 6, 7, 8) else (w, h)


def read_image(path: str | Path) -> tuple[np.ndarray, dict]:
    """Decode one photo, upright.

    Returns:
        rgb: [H, W, 3] uint8 sRGB.
        info: ``format``, ``orientation``, ``make``, ``model``, ``focal_mm``, ``focal_35mm``,
            ``has_gps``, ``exif`` (raw EXIF bytes to carry into a JPEG copy, or b"").
    Raises:
        ValueError / OSError with a readable message when the file cannot be used.
    """
    from PIL import Image, ImageOps

    path = Path(path)
    if path.stat().st_size == 0:
        raise ValueError("empty file (0 bytes)")
    ext = path.suffix.lower()
    if ext in RAW_EXTS:
        import rawpy
        try:
            with rawpy.imread(str(path)) as raw:
                rgb = raw.postprocess(use_camera_wb=True, output_bps=8, output_color=rawpy.ColorSpace.sRGB)
        except Exception as e:  # noqa: BLE001 - rawpy raises its own LibRawError family
            raise ValueError(f"RAW decode failed: {type(e).__name__}: {e}") from e
        info = {"format": "raw", "exif": b""}
        try:  # DNG and several RAWs are TIFF-based: Pillow may read their EXIF
            with Image.open(path) as im:
                info.update(_exif_info(im))
                info["orientation"] = 1  # rawpy already applied the RAW's flip
        except Exception:  # noqa: BLE001
            pass
        return np.ascontiguousarray(rgb), info
    try:
        with Image.open(path) as im:
            fmt = (im.format or "").lower()
            if fmt not in ("jpeg", "png", "tiff", "mpo"):
                raise ValueError(f"unsupported image format {im.format!r}")
            im.load()  # raises OSError on truncated data
            info = {"format": "jpeg" if fmt == "mpo" else fmt}
            info.update(_exif_info(im))
            up = ImageOps.exif_transpose(im)
            exif = up.getexif()
            info["exif"] = exif.tobytes() if len(exif) else b""
            rgb = _to_rgb8(up)
    except ValueError:
        raise
    except Exception as e:  # noqa: BLE001 - UnidentifiedImageError, truncated, decoder errors
        raise ValueError(f"cannot decode: {type(e).__name__}: {e}") from e
    return rgb, info
