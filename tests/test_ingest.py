"""Ingest and quality: bad files are skipped with reasons, RAW decodes, the input folder is never written."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

from curate.core.images import read_image
from curate.sfm.ingest import find_images, ingest, working_name
from curate.sfm.quality import assess, hamming, phash, sharpness

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


def need(sub: str) -> Path:
    p = DATA / sub
    if not p.exists():
        pytest.skip(f"sample data {p} not present (expected ../shared/data next to the repository)")
    return p


def sha_tree(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def make_mixed_folder(folder: Path, n_good: int = 10, size: int = 480) -> Path:
    """Fox photos (downscaled) as good JPEGs + one PNG, plus a truncated JPEG, a text '.jpg', an empty file."""
    from PIL import Image
    fox = need("fox/images")
    folder.mkdir(parents=True, exist_ok=True)
    srcs = sorted(fox.glob("*.jpg"))[:n_good + 1]
    for p in srcs[:n_good]:
        im = Image.open(p)
        im.thumbnail((size, size), Image.LANCZOS)
        im.save(folder / p.name, quality=92)
    im = Image.open(srcs[n_good])
    im.thumbnail((size, size), Image.LANCZOS)
    im.save(folder / "extra.png")
    data = (folder / srcs[0].name).read_bytes()
    (folder / "zz_truncated.jpg").write_bytes(data[: len(data) // 3])
    (folder / "zz_text.jpg").write_text("this is not a JPEG\n")
    (folder / "zz_empty.jpg").write_bytes(b"")
    (folder / "notes.txt").write_text("capture notes\n")
    return folder


def test_bad_files_are_skipped_and_input_untouched(tmp_path):
    photos = make_mixed_folder(tmp_path / "photos")
    before = sha_tree(photos)
    recs = ingest(photos, tmp_path / "run" / "images", max_size=300, progress=False)
    assert sha_tree(photos) == before
    by = {r.rel: r for r in recs}
    assert len(recs) == len(before)
    for bad in ("zz_truncated.jpg", "zz_text.jpg", "zz_empty.jpg", "notes.txt"):
        assert by[bad].status == "skipped" and by[bad].reason, bad
    assert "empty" in by["zz_empty.jpg"].reason
    assert "truncated" in by["zz_truncated.jpg"].reason.lower()
    assert "extension" in by["notes.txt"].reason
    good = [r for r in recs if r.status == "kept"]
    assert len(good) == 11
    for r in good:
        w = tmp_path / "run" / "images" / r.working
        assert w.is_file() and max(r.width, r.height) <= 300
        assert r.orig_height == 480 and r.orig_width == 270
        assert r.scale_x == pytest.approx(r.width / r.orig_width)
    assert by["extra.png"].working == "extra.png" and by["extra.png"].format == "png"


def test_exif_orientation_applied(tmp_path):
    from PIL import Image
    a = np.zeros((40, 80, 3), np.uint8)
    a[:, :40] = 255  # left half white
    im = Image.fromarray(a)
    exif = im.getexif()
    exif[274] = 6  # rotate 90 CW to display
    im.save(tmp_path / "o.jpg", exif=exif.tobytes(), quality=95)
    rgb, info = read_image(tmp_path / "o.jpg")
    assert info["orientation"] == 6
    assert rgb.shape == (80, 40, 3)  # upright: portrait
    assert rgb[:40].mean() > 200 and rgb[40:].mean() < 50  # white left half is now on top


def test_working_names_unique():
    assert working_name("a/IMG_1.CR2", "raw") == "a__IMG_1.CR2.jpg"
    assert working_name("IMG_1.JPG", "jpeg") == "IMG_1.JPG"
    assert working_name("x.tif", "tiff") == "x.tif.png"
    assert working_name("x.png", "png") == "x.png"


def test_recursive_find(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "a.jpg").write_bytes(b"x")
    (tmp_path / "sub" / "b.png").write_bytes(b"x")
    (tmp_path / ".hidden.jpg").write_bytes(b"x")
    assert [p.name for p in find_images(tmp_path)[0]] == ["a.jpg"]
    assert [p.name for p in find_images(tmp_path, recursive=True)[0]] == ["a.jpg", "b.png"]


def test_raw_decode_sizes():
    raw = need("raw")
    rgb, info = read_image(raw / "Blackmagic_PocketCinemaCamera4K_12bit.dng")
    assert rgb.shape == (2176, 4128, 3) and rgb.dtype == np.uint8 and info["format"] == "raw"
    rgb, info = read_image(raw / "RAW_KODAK_DC50.KDC")
    assert rgb.shape == (512, 768, 3) and rgb.dtype == np.uint8
    assert info.get("make", "").startswith("Eastman Kodak")


def test_raw_mixed_with_jpeg(tmp_path):
    raw, fox = need("raw"), need("fox/images")
    photos = tmp_path / "photos"
    photos.mkdir()
    for p in sorted(raw.iterdir()):
        (photos / p.name).symlink_to(p)
    for p in sorted(fox.glob("*.jpg"))[:2]:
        (photos / p.name).symlink_to(p)
    recs = ingest(photos, tmp_path / "work", max_size=600, progress=False)
    by = {r.rel: r for r in recs}
    assert all(r.status == "kept" for r in recs), [(r.rel, r.reason) for r in recs]
    dng = by["Blackmagic_PocketCinemaCamera4K_12bit.dng"]
    assert (dng.orig_height, dng.orig_width) == (2176, 4128)
    assert (dng.height, dng.width) == (round(2176 * 600 / 4128), 600)
    assert dng.working.endswith(".dng.jpg") and (tmp_path / "work" / dng.working).is_file()
    kdc = by["RAW_KODAK_DC50.KDC"]
    assert (kdc.orig_height, kdc.orig_width, kdc.height, kdc.width) == (512, 768, 400, 600)
    assert (by["0001.jpg"].orig_height, by["0001.jpg"].height) == (1920, 600)


def test_quality_duplicates_and_blur():
    rng = np.random.default_rng(0)
    base = (rng.random((120, 160, 3)) * 255).astype(np.uint8)
    from scipy.ndimage import gaussian_filter
    base = gaussian_filter(base.astype(float), (2, 2, 0)).astype(np.uint8)
    near = np.clip(base.astype(int) + rng.integers(-2, 3, base.shape), 0, 255).astype(np.uint8)
    other = np.ascontiguousarray(base[::-1, ::-1])
    blurred = gaussian_filter(base.astype(float), (6, 6, 0)).astype(np.uint8)
    imgs = [base, near, other, blurred]
    s = np.array([sharpness(x) for x in imgs])
    h = np.stack([phash(x) for x in imgs])
    assert hamming(h[:1], h[1:2])[0, 0] <= 4 and hamming(h[:1], h[2:3])[0, 0] > 40
    blurry, dup_of, _ = assess(s, h, blur_fraction=0.3, dup_max_distance=4)
    assert s[3] < 0.3 * np.median(s) and blurry[3] and not blurry[:3].any()
    assert {int(dup_of[0]), int(dup_of[1])} in ({-1, 0}, {-1, 1})  # exactly one of the pair is a duplicate
    assert dup_of[2] == -1


def test_images_json_records_skips(tmp_path):
    """The SfM stage's images.json lists skipped files with reasons (ingest + quality only, no COLMAP)."""
    from curate.sfm.config import SfmConfig
    from curate.sfm.prep import prepare_photos, write_outputs
    from curate.core.cameras import Cameras
    photos = make_mixed_folder(tmp_path / "photos", n_good=3)
    (photos / "copy_of_0001.jpg").write_bytes((photos / "0001.jpg").read_bytes())  # an exact duplicate
    out = tmp_path / "run" / "sfm"
    recs, kept, t = prepare_photos(SfmConfig(max_image_size=200, progress=False), photos, out)
    write_outputs(out, Cameras.empty(), None, None, None, recs, [], 1.0)
    j = json.loads((out / "images.json").read_text())
    st = {r["rel"]: (r["status"], r["reason"]) for r in j["photos"]}
    assert st["zz_empty.jpg"][0] == "skipped" and st["zz_text.jpg"][0] == "skipped"
    assert j["summary"]["kept"] == 4 and j["summary"]["registered"] == 0
    dup = [r for r in j["photos"] if r["status"] == "dropped"]
    assert len(dup) == 1 and "near-duplicate" in dup[0]["reason"]
    assert {dup[0]["rel"], dup[0]["extra"]["duplicate_of"]} == {"0001.jpg", "copy_of_0001.jpg"}
    assert not (out / "images" / dup[0]["working"]).exists()


def test_later_stages_do_not_import_pycolmap():
    """Only curate.sfm may import pycolmap, and only inside its functions."""
    import subprocess
    import sys
    code = ("import sys, curate.sfm.colmap, curate.sfm.pose_import, curate.sfm.parts, curate.sfm.continuity, "
            "curate.sfm.undistort, curate.sfm.io, curate.sfm.prep, curate.sfm.ingest, curate.sfm.quality, "
            "research.align, research.datasets; assert 'pycolmap' not in sys.modules, 'pycolmap imported'")
    r = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).resolve().parents[1],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_broken_links_in_the_photo_folder_are_listed_with_their_reason(tmp_path):
    """Issue 49: a dangling link and a link loop among the photos are skipped and listed (the README promises
    every skipped file with its reason), never dropped without a word; the photos around them are kept."""
    import os
    from PIL import Image
    folder = tmp_path / "photos"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(3):
        Image.fromarray(rng.integers(0, 255, (24, 32, 3), np.uint8)).save(folder / f"img_{i}.png")
    os.symlink(tmp_path / "gone.jpg", folder / "dangling.jpg")
    os.symlink(folder / "loop_b.jpg", folder / "loop_a.jpg")
    os.symlink(folder / "loop_a.jpg", folder / "loop_b.jpg")
    os.symlink(tmp_path / "gone.txt", folder / "notes.txt")
    recs = {r.rel: r for r in ingest(folder, tmp_path / "work", progress=False)}
    assert sorted(recs) == ["dangling.jpg", "img_0.png", "img_1.png", "img_2.png", "loop_a.jpg", "loop_b.jpg",
                            "notes.txt"]
    assert [recs[f"img_{i}.png"].status for i in range(3)] == ["kept"] * 3
    assert recs["dangling.jpg"].status == "skipped" and "target is gone" in recs["dangling.jpg"].reason
    assert "gone.jpg" in recs["dangling.jpg"].reason
    assert all("link loop" in recs[n].reason and recs[n].status == "skipped" for n in ("loop_a.jpg", "loop_b.jpg"))
    assert recs["notes.txt"].status == "skipped" and "target is gone" in recs["notes.txt"].reason
