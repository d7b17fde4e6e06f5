"""Known poses with a photo folder: each pose finds its photo there, or is left out and listed; every
command reads the same pose sources; poses without points get points triangulated with the poses fixed."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from curate.cli import main
from curate.core.transforms_json import read_transforms, write_transforms

from test_export import ring, write_photos

pycolmap = pytest.importorskip("pycolmap")
from curate.sfm.config import SfmConfig  # noqa: E402
from curate.sfm.model import reconstruction_from_cameras  # noqa: E402
from curate.sfm.pose_import import import_poses  # noqa: E402
from curate.sfm.io import load_sfm  # noqa: E402
from curate.sfm.poses import match_photos  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
FAST = ["--no-evaluate", "--method", "medoids", "--budget", "3", "--res", "8", "--triangulate", "off"]


def capture(root: Path, n: int = 12) -> tuple[Path, object]:
    """``root``: images/img_XX.png (noise), transforms.json (file paths images/...), sparse/0 (COLMAP model,
    names img_XX.png, the usual layout beside images/), cameras.json (names images/img_XX.png)."""
    from curate.core.cameras import Cameras
    c = ring(n)
    cams = Cameras(c.c2w, c.fx, c.fy, c.cx, c.cy, c.width, c.height, c.dist,
                   tuple(f"images/img_{i:02d}.png" for i in range(n)))
    write_photos(root, cams)
    write_transforms(root / "transforms.json", cams)
    bare = Cameras(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height, cams.dist,
                   tuple(Path(nm).name for nm in cams.names))
    (root / "sparse" / "0").mkdir(parents=True)
    reconstruction_from_cameras(bare).write(root / "sparse" / "0")
    cams.save(root / "cameras.json")   # names images/img_XX.png, relative to its folder
    return root, bare


def one_line_error(capsys) -> str:
    err = [ln for ln in capsys.readouterr().err.replace("\r", "\n").splitlines() if ln.startswith("curate ")]
    assert len(err) == 1, err
    return err[0]


# ------------------------------------------------------------------ matching poses to a folder's photos
def test_each_pose_finds_its_photo_by_path_else_by_its_unique_name(tmp_path):
    f = tmp_path / "photos"
    (f / "sub").mkdir(parents=True)
    for n in ("a.jpg", "sub/b.jpg", "c.png", "d.jpg", "sub/d.jpg", "extra.jpg"):
        (f / n).write_bytes(b"x")
    (f / "clip.mp4").write_bytes(b"x")
    names = ["a.jpg", "elsewhere/b.jpg", "r_c", "d.jpg", "x/e.jpg", "y/e.jpg", "missing.jpg"]
    m = match_photos(names, [""] * len(names), f, recursive=True)
    got = dict(zip(names, m.files))
    assert got["a.jpg"] == str((f / "a.jpg").resolve())           # by its path in the folder
    assert got["elsewhere/b.jpg"] == str((f / "sub/b.jpg").resolve())  # by its unique file name
    assert got["d.jpg"] == str((f / "d.jpg").resolve())           # the path wins over two photos named d.jpg
    assert got["r_c"] is None and got["missing.jpg"] is None
    assert got["x/e.jpg"] is None and got["y/e.jpg"] is None       # no photo e.jpg
    assert sorted(p.name for p in m.unposed) == ["c.png", "clip.mp4", "d.jpg", "extra.jpg"]
    assert m.n_photos == 7 and m.how[names.index("elsewhere/b.jpg")] == "name"
    # a Blender-synthetic name without extension is found with one; a base name shared by two poses is unclear
    m = match_photos(["c", "x/extra.jpg", "y/extra.jpg"], [""] * 3, f)
    assert m.files[0] == str((f / "c.png").resolve()) and m.files[1] is None and "2 poses" in m.how[1]
    # two photos of the folder with the pose's name: unclear, left out with that reason
    m = match_photos(["z/d.jpg"], [""], f, recursive=True)
    assert m.files == [None] and "2 photos" in m.how[0]


def test_a_photo_folder_of_another_capture_is_refused_naming_both(tmp_path, capsys):
    cap, _ = capture(tmp_path / "cap")
    other = tmp_path / "other"
    other.mkdir()
    for i in range(31):
        shutil.copy(cap / "images" / "img_00.png", other / f"IMG_{i:04d}.png")
    for cmd in ("run", "sfm"):
        out = tmp_path / f"run_{cmd}"
        assert main([cmd, str(other), "--poses", str(cap / "transforms.json"), "--out", str(out),
                     *(FAST if cmd == "run" else [])]) == 2
        err = one_line_error(capsys)
        assert str(other) in err and str(cap / "transforms.json") in err
        assert "images/img_00.png" in err and "IMG_0000.png" in err
        assert not (out / "sfm" / "cameras.json").exists()


def test_a_video_with_poses_is_refused(tmp_path, capsys):
    cap, _ = capture(tmp_path / "cap")
    video = tmp_path / "walk.mp4"
    video.write_bytes(b"\x00\x00\x00\x18ftypmp42")
    assert main(["run", str(video), "--poses", str(cap / "transforms.json"), "--out", str(tmp_path / "r"), *FAST]) == 2
    err = one_line_error(capsys)
    assert str(video) in err and "video" in err and "no names the poses could refer to" in err


def test_a_folder_holding_a_fraction_of_the_posed_photos_curates_those_and_warns(tmp_path, capsys):
    """5 photos and the 20 poses of their capture: the 5 are curated, the 15 poses without a photo and the
    folder's photo without a pose are listed in images.json (and the report), and the run says so at its
    end and atop the report."""
    cap, _ = capture(tmp_path / "cap", n=20)
    few = tmp_path / "few"
    few.mkdir()
    for i in range(5):
        shutil.copy(cap / "images" / f"img_{i:02d}.png", few)
    shutil.copy(cap / "images" / "img_00.png", few / "holiday.png")
    out = tmp_path / "run"
    assert main(["run", str(few), "--poses", str(cap / "transforms.json"), "--out", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    cams = load_sfm(out).cameras
    assert len(cams) == 5 and "5 cameras registered (imported, of 20 poses)" in text
    assert "WARNING (sfm): only 5 of the 20 poses" in text and str(few) in text
    recs = json.loads((out / "sfm" / "images.json").read_text())["photos"]
    left = {r["rel"]: r["reason"] for r in recs if r["status"] == "skipped"}
    assert len(left) == 16 and "no pose in" in left["holiday.png"]
    assert left["images/img_19.png"].startswith("pose without a photo: no photo images/img_19.png")
    rep = json.loads((out / "report.json").read_text())
    assert len(rep["sfm"]["skipped"]) == 16
    export = json.loads((out / "export" / "stage.json").read_text())
    assert "only 5 of the 20 poses" in export["warning"]
    # the pose file's own photos were never used: every chosen photo is one of the folder's
    assert all(Path(i["original"]).parent == few.resolve()
               for i in json.loads((out / "export" / "export.json").read_text())["images"])


def test_a_photo_folder_with_most_photos_posed_goes_on_quietly(tmp_path, capsys):
    """A COLMAP model that left 2 of 12 photos out: the 10 are curated, the 2 listed, no loud warning."""
    cap, bare = capture(tmp_path / "cap")
    model = tmp_path / "model"
    model.mkdir()
    reconstruction_from_cameras(bare[list(range(10))]).write(model)
    out = tmp_path / "run"
    assert main(["run", str(cap / "images"), "--poses", str(model), "--out", str(out), *FAST]) == 0
    text = capsys.readouterr().out
    assert len(load_sfm(out).cameras) == 10 and "WARNING (sfm)" not in text
    recs = json.loads((out / "sfm" / "images.json").read_text())["photos"]
    assert sorted(r["rel"] for r in recs if r["status"] == "skipped") == ["img_10.png", "img_11.png"]


# ------------------------------------------------------------------ every command, the same sources
def test_run_and_select_accept_the_same_pose_sources(tmp_path, capsys):
    """Each source, with the photo folder and without one (its own image paths, or the images/ beside a
    COLMAP model): `run --poses` curates the 12 cameras, `select` chooses from them with the photos found."""
    cap, bare = capture(tmp_path / "cap")
    colmap_only = tmp_path / "colmap_scene"   # a folder holding sparse/0 and images/ (no transforms.json)
    shutil.copytree(cap / "sparse", colmap_only / "sparse")
    shutil.copytree(cap / "images", colmap_only / "images")
    sources = [cap / "transforms.json", cap, cap / "sparse" / "0", colmap_only, cap / "cameras.json"]
    for k, src in enumerate(sources):
        sel = tmp_path / f"sel{k}"
        assert main(["select", str(src), "--budget", "3", "--out", str(sel), "--method", "medoids", "--res", "8"]) == 0
        chosen, files = read_transforms(sel / "transforms.json", contained=False)   # curate select's own paths
        assert len(chosen) == 3 and all(Path(f).is_file() for f in files), src
        run = tmp_path / f"run{k}"
        for ph in ([str(cap / "images")], []):
            capsys.readouterr()
            assert main(["run", *ph, "--poses", str(src), "--out", str(run), *FAST]) == 0, capsys.readouterr().err
            cams = load_sfm(run).cameras
            assert len(cams) == 12 and np.allclose(np.sort(cams.centres, 0), np.sort(bare.centres, 0)), src
            assert len(list((run / "export" / "images").iterdir())) == 3


# ------------------------------------------------------------------ points for known poses
def walk(dst: Path, frames: range) -> Path:
    """Frames of the sample walk in ``dst/images`` and their poses in ``dst/transforms.json``."""
    tj = json.loads((SAMPLE / "transforms.json").read_text())
    tj["frames"] = [tj["frames"][i] for i in frames]
    (dst / "images").mkdir(parents=True)
    for f in tj["frames"]:
        shutil.copy2(SAMPLE / f["file_path"], dst / f["file_path"])
    (dst / "transforms.json").write_text(json.dumps(tj))
    return dst


def test_points_are_triangulated_for_known_poses_and_exported(tmp_path):
    """16 frames of the rendered walk, at a working size below theirs (200 of 320 px): points with tracks
    in RUN/sfm/sparse/0 and points.npy, the poses and intrinsics untouched, keypoints at the photos' own
    size (the points reproject within a pixel there), and the export keeps the points its images see."""
    from curate.export.subset import export_subset
    from curate.sfm.model import cameras_from_reconstruction
    cap = walk(tmp_path / "cap", range(0, 32, 2))
    ref, _ = read_transforms(cap / "transforms.json")
    run = tmp_path / "run"
    import_poses(SfmConfig(progress=False, max_image_size=200), cap / "transforms.json", run, photos=cap / "images")
    st = json.loads((run / "sfm" / "stage.json").read_text())["stats"]
    tri = st["triangulation"]
    assert tri["status"] == "done" and tri["working_max_side"] == 200 and tri["camera_mode"] == "single"
    assert tri["n_points"] >= 300 and tri["mean_track_length"] >= 3 and tri["mean_reprojection_error_px"] < 1.0
    rec = pycolmap.Reconstruction(str(run / "sfm" / "sparse" / "0"))
    cams, xyz, _, err = cameras_from_reconstruction(rec)
    assert rec.num_points3D() == tri["n_points"] == st["n_points"] == len(np.load(run / "sfm" / "points.npy"))
    assert np.allclose(np.sort(xyz, 0), np.sort(np.load(run / "sfm" / "points.npy"), 0), atol=1e-5)
    by = {n: i for i, n in enumerate(ref.names)}
    idx = [by[n] for n in cams.names]
    assert np.allclose(cams.c2w, ref.c2w[idx], atol=1e-6)
    for k in ("fx", "fy", "cx", "cy", "width", "height"):
        assert np.allclose(getattr(cams, k), getattr(ref, k)[idx]), k
    assert rec.compute_mean_reprojection_error() < 320 / 200 * 1.0 and np.all(np.isfinite(err))
    assert all(len(p.track.elements) >= 2 for p in rec.points3D.values())
    assert not (run / "sfm" / "triangulation").exists()   # the working copies are gone
    # unchanged photos, poses and options: the stage is skipped, its record untouched
    record = (run / "sfm" / "stage.json").read_bytes()
    import_poses(SfmConfig(progress=False, max_image_size=200), cap / "transforms.json", run, photos=cap / "images")
    assert (run / "sfm" / "stage.json").read_bytes() == record
    # the export: the chosen images and the points two of them see
    chosen = list(ref.names[:8])
    export_subset(run, chosen, run / "export")
    model = json.loads((run / "export" / "export.json").read_text())["model"]
    assert 0 < model["n_points3D"] <= tri["n_points"] and model["n_images_with_points"] == 8
    assert sum(model["components"]) == 8 and model["components"][0] >= 7   # linked through shared points


def test_triangulation_is_skipped_when_off_or_when_the_source_has_points(tmp_path):
    cap = walk(tmp_path / "cap", range(0, 12))
    off = tmp_path / "off"
    import_poses(SfmConfig(progress=False, triangulate="off"), cap / "transforms.json", off, photos=cap / "images")
    st = json.loads((off / "sfm" / "stage.json").read_text())["stats"]
    assert st["triangulation"]["status"] == "off" and st["n_points"] == 0
    on = tmp_path / "on"
    import_poses(SfmConfig(progress=False), cap / "transforms.json", on, photos=cap / "images")
    n = json.loads((on / "sfm" / "stage.json").read_text())["stats"]["n_points"]
    assert n > 0
    # a COLMAP model with points (the one just written) is imported as it is, with its points
    again = tmp_path / "again"
    import_poses(SfmConfig(progress=False), on / "sfm" / "sparse" / "0", again, photos=cap)
    st = json.loads((again / "sfm" / "stage.json").read_text())["stats"]
    assert st["triangulation"]["status"] == "source" and st["n_points"] == n and st["pose_match"]["n_matched"] == 12
    # the same model with two photos missing from the folder: the points the other ten see are kept
    part = tmp_path / "part"
    shutil.copytree(cap, part)
    for f in sorted((part / "images").iterdir())[:2]:
        f.unlink()
    again2 = tmp_path / "again2"
    import_poses(SfmConfig(progress=False), on / "sfm" / "sparse" / "0", again2, photos=part)
    st = json.loads((again2 / "sfm" / "stage.json").read_text())["stats"]
    rec = pycolmap.Reconstruction(str(again2 / "sfm" / "sparse" / "0"))
    assert rec.num_reg_images() == 10 and 0 < st["n_points"] == rec.num_points3D() <= n


def test_no_points_from_the_photos_is_said_in_the_sfm_and_export_stages(tmp_path, capsys):
    """Noise photos: no verified matches, no points; the run goes on and says the export has no points."""
    cap, _ = capture(tmp_path / "cap")
    out = tmp_path / "run"
    fast = [a for a in FAST if a not in ("--triangulate", "off")]
    assert main(["run", str(cap / "images"), "--poses", str(cap / "transforms.json"), "--out", str(out), *fast]) == 0
    text = capsys.readouterr().out
    st = json.loads((out / "sfm" / "stage.json").read_text())["stats"]
    assert st["triangulation"]["status"] == "done" and st["triangulation"]["n_points"] == 0
    assert "WARNING (sfm): triangulating the photos with the known poses found no 3D points" in text
    assert "WARNING (export): the export has no 3D points: 3DGS needs an initial point cloud" in text
    export = json.loads((out / "export" / "stage.json").read_text())
    assert "the export has no 3D points" in export["warning"]   # atop the report


def test_points_warning_says_why():
    from curate.export.stage import points_warning
    assert points_warning({"n_points3D": 500}) is None
    off = points_warning({"n_points3D": 0}, {"mode": "import", "stats": {"triangulation": {"status": "off"}}})
    assert (off.startswith("the export has no 3D points: 3DGS needs an initial point cloud")
            and "--triangulate auto" in off)
    few = points_warning({"n_points3D": 12, "n_points3D_source": 900}, {"mode": "sfm", "stats": {}})
    assert few.startswith("the export has only 12 3D points") and "larger budget" in few


@pytest.mark.slow
def test_fox_poses_get_points_that_fit_them(tmp_path):
    """The fox's published poses (transforms.json with OPENCV distortion) and its photos: thousands of
    points, tracks of several photos, sub-pixel reprojection at the working size (320 px, as the fox's SfM in
    tests/test_sfm.py: 3,425 points, tracks of 7.6 photos, 0.41 px on 2026-11-30)."""
    from test_ingest import need
    src = need("fox") / "transforms.json"
    run = tmp_path / "run"
    import_poses(SfmConfig(progress=False, max_image_size=320), src, run)
    tri = json.loads((run / "sfm" / "stage.json").read_text())["stats"]["triangulation"]
    assert tri["status"] == "done" and tri["n_points"] >= 2000, tri
    assert tri["mean_track_length"] >= 3 and tri["mean_reprojection_error_px"] < 1.5, tri
    assert tri["n_images_with_points"] >= 0.95 * tri["n_images"]


@pytest.mark.parametrize("factor, said", [(0.5, "intrinsics scaled by 1/2"), (2.0, "intrinsics scaled by 2")])
@pytest.mark.parametrize("source", ["transforms.json", "sparse/0"])
def test_poses_for_another_size_of_the_photos_export_the_photos_cameras(tmp_path, capsys, factor, said, source):
    """Issue 49: poses written for the full-size images with the photos downscaled (nerfstudio's images_2,
    images_4), or the reverse: the run says so in one line, and the export's transforms.json and sparse/0
    describe the photos they name, their size and their intrinsics scaled; another aspect is an error."""
    from PIL import Image
    root = tmp_path / "cap"
    _, cams = capture(root)
    w, h = int(round(64 * factor)), int(round(48 * factor))
    for p in (root / "images").iterdir():                  # the photos at another size, same aspect
        Image.open(p).resize((w, h)).save(p)
    run = tmp_path / "run"
    assert main(["run", str(root / "images"), "--poses", str(root / source), "--out", str(run), *FAST]) == 0
    out = capsys.readouterr().out
    assert f"poses are for 64x48, photos are {w}x{h}: {said}" in out
    tj = json.loads((run / "export" / "transforms.json").read_text())
    for fr in tj["frames"]:
        W, H = fr.get("w", tj.get("w")), fr.get("h", tj.get("h"))
        fx = fr.get("fl_x", tj.get("fl_x"))
        assert (W, H) == (w, h) and fx == pytest.approx(55.0 * factor)
        with Image.open(run / "export" / fr["file_path"]) as im:
            assert im.size == (W, H)                        # the cameras match the images they name
    rec = pycolmap.Reconstruction(str(run / "export" / "sparse" / "0"))
    for cam in rec.cameras.values():
        assert (cam.width, cam.height) == (w, h) and cam.focal_length_x == pytest.approx(55.0 * factor)
    bad = root / "images" / "img_03.png"                    # another aspect: refused, naming the file
    Image.open(bad).resize((w, w)).save(bad)
    assert main(["run", str(root / "images"), "--poses", str(root / source), "--out", str(tmp_path / "r2"),
                 *FAST]) == 2
    err = one_line_error(capsys)
    assert "img_03.png" in err and f"{w}x{w}" in err and "another aspect ratio" in err


def test_a_transforms_json_without_image_sizes_reads_them_from_the_photos_found_in_the_folder(tmp_path, capsys):
    """Issue 49: w and h left out of a transforms.json whose file paths do not lead to the photos (they were
    moved): the photo found by name in the photo folder gives the size; with no photo to read, a one-line
    error says what to add."""
    root = tmp_path / "cap"
    _, cams = capture(root)
    meta = json.loads((root / "transforms.json").read_text())
    for k in ("w", "h"):
        meta.pop(k, None)
        for fr in meta["frames"]:
            fr.pop(k, None)
    for fr in meta["frames"]:
        fr["file_path"] = "elsewhere/" + Path(fr["file_path"]).name
    poses = tmp_path / "poses" / "transforms.json"
    poses.parent.mkdir()
    poses.write_text(json.dumps(meta))
    run = tmp_path / "run"
    assert main(["run", str(root / "images"), "--poses", str(poses), "--out", str(run), *FAST]) == 0
    res = load_sfm(run)
    assert len(res.cameras) == 12 and set(res.cameras.width) == {64} and set(res.cameras.height) == {48}
    assert main(["run", "--poses", str(poses), "--out", str(tmp_path / "r2"), *FAST]) == 2
    err = one_line_error(capsys)
    assert "transforms.json" in err and 'add "w" and "h"' in err


def test_a_link_loop_in_the_photo_folder_does_not_stop_a_pose_import(tmp_path):
    """A link loop among the photos (read by no pose) raised Python's 'Symlink loop' while the poses' photos
    were looked up: the import goes on, and the loop is listed among the skipped files."""
    import os
    cap, _ = capture(tmp_path / "cap")
    os.symlink(cap / "images" / "loop_b.jpg", cap / "images" / "loop_a.jpg")
    os.symlink(cap / "images" / "loop_a.jpg", cap / "images" / "loop_b.jpg")
    (cap / "images" / "gone.jpg").symlink_to(tmp_path / "nowhere.jpg")
    m = match_photos([f"images/img_{i:02d}.png" for i in range(12)], [""] * 12, cap / "images")
    assert all(f is not None for f in m.files)
    run = tmp_path / "run"
    assert main(["run", str(cap / "images"), "--poses", str(cap / "transforms.json"), "--out", str(run), *FAST]) == 0
    assert len(load_sfm(run).cameras) == 12


def test_a_colmap_image_with_a_zero_quaternion_is_an_error_naming_the_file_and_image(tmp_path):
    """The adversarial sweep (issue 49): `0 0 0 0` in images.txt was read as the identity rotation and exported."""
    import numpy as np
    from curate.core.cameras import Cameras, look_at
    from curate.sfm.model import read_colmap_model, reconstruction_from_cameras
    c = np.array([[3.0, 0, 0], [0, 3.0, 0], [-3, 0, 0]])
    rec = reconstruction_from_cameras(Cameras(look_at(c, np.zeros((3, 3))), 50.0, 50.0, 32.0, 24.0, 64, 48,
                                              names=("a.jpg", "b.jpg", "c.jpg")))
    for kind in ("txt", "bin"):
        d = tmp_path / kind
        d.mkdir()
        (rec.write_text if kind == "txt" else rec.write)(str(d))
        assert len(read_colmap_model(d, None).cameras) == 3
    txt = tmp_path / "txt" / "images.txt"
    lines = txt.read_text().splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.endswith(" b.jpg"))
    f = lines[i].split()
    lines[i] = " ".join([f[0], "0", "0", "0", "0"] + f[5:])
    txt.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"images.txt: image b.jpg has a rotation quaternion of zero length"):
        read_colmap_model(tmp_path / "txt", None)


# ------------------------------------------------------------------ a pose file never reaches outside its capture
def _secret(tmp_path) -> Path:
    """A readable image outside every capture folder of these tests: the file a hostile pose file points at."""
    from PIL import Image
    s = tmp_path / "elsewhere" / "secret.png"
    s.parent.mkdir()
    Image.fromarray(np.full((48, 64, 3), 7, np.uint8)).save(s)
    return s


def _text_secret(tmp_path) -> Path:
    s = tmp_path / "elsewhere" / "passwd"
    s.parent.mkdir(exist_ok=True)
    s.write_text("root:x:0:0:root:/root:/bin/bash\n")
    return s


def _no_secret_exported(run: Path) -> None:
    assert not (run / "export").exists() or not any("secret" in p.name or p.name == "passwd"
                                                     for p in (run / "export").rglob("*"))


@pytest.mark.parametrize("kind", ["txt", "bin"])
def test_a_colmap_model_naming_a_file_outside_the_capture_is_refused_before_anything_is_read(
        tmp_path, capsys, monkeypatch, kind):
    """The sweep's security finding (issue 61): images.txt naming ../../../../../etc/passwd, run from the photo
    folder without giving it, copied /etc/passwd into RUN/export/images. The names were resolved against the
    working directory and never checked."""
    root, bare = capture(tmp_path / "cap")
    secret = _secret(tmp_path)
    from curate.core.cameras import Cameras
    hops = "../" * len(Path(os.path.relpath(root / "images", "/")).parts)
    names = list(bare.names)
    names[3] = hops + os.path.relpath(secret, "/")       # ../../../../tmp/.../elsewhere/secret.png
    names[5] = str(secret)                               # and an absolute path
    model = tmp_path / "model"
    model.mkdir()
    rec = reconstruction_from_cameras(Cameras(bare.c2w, bare.fx, bare.fy, bare.cx, bare.cy, bare.width, bare.height,
                                              bare.dist, tuple(names)))
    (rec.write_text if kind == "txt" else rec.write)(str(model))
    monkeypatch.chdir(root / "images")
    run = tmp_path / "run"
    assert main(["run", "--poses", str(model), "--budget", "11", "--no-evaluate", "--undistort", "off",
                 "--export-mode", "copy", "--out", str(run), "--triangulate", "off"]) == 2
    err = one_line_error(capsys)
    assert f"images.{kind}" in err and "outside the capture's folder" in err and "secret.png" in err
    _no_secret_exported(run)


@pytest.mark.parametrize("how", ["climbs", "absolute", "link"])
def test_a_transforms_json_naming_a_file_outside_its_folder_is_refused_naming_the_frame(tmp_path, capsys, how):
    root, _ = capture(tmp_path / "cap")
    secret = _secret(tmp_path)
    data = json.loads((root / "transforms.json").read_text())
    if how == "link":    # a link to a file that is not a photo (a link to a photo elsewhere is a photo: below)
        (root / "images" / "img_04.png").unlink()
        (root / "images" / "img_04.png").symlink_to(_text_secret(tmp_path))
    else:
        data["frames"][4]["file_path"] = os.path.relpath(secret, root) if how == "climbs" else str(secret)
    (root / "transforms.json").write_text(json.dumps(data))
    run = tmp_path / "run"
    assert main(["run", "--poses", str(root / "transforms.json"), "--out", str(run), "--export-mode", "copy",
                 *FAST]) == 2
    err = one_line_error(capsys)
    assert "transforms.json: frame 4 names" in err and "outside the capture's folder" in err, err
    assert ("a link that leads to" in err) == (how == "link")
    _no_secret_exported(run)


def test_a_cameras_json_naming_a_file_outside_its_folder_is_refused(tmp_path, capsys):
    root, _ = capture(tmp_path / "cap")
    secret = _secret(tmp_path)
    data = json.loads((root / "cameras.json").read_text())
    data["cameras"][2]["name"] = str(secret)
    (root / "cameras.json").write_text(json.dumps(data))
    assert main(["run", "--poses", str(root / "cameras.json"), "--out", str(tmp_path / "run"), *FAST]) == 2
    err = one_line_error(capsys)
    assert "cameras.json: camera 2 names" in err and "an absolute path elsewhere" in err


def test_with_a_photo_folder_a_pose_finds_its_photo_only_inside_it(tmp_path, capsys):
    """A name that climbs out is looked up by its file name in the folder, never opened where it points; a photo
    of the folder that is a link out is refused."""
    root, _ = capture(tmp_path / "cap")
    secret = _secret(tmp_path)
    data = json.loads((root / "transforms.json").read_text())
    data["frames"][1]["file_path"] = os.path.relpath(secret, root)   # ../elsewhere/secret.png: no such photo here
    (root / "transforms.json").write_text(json.dumps(data))
    run = tmp_path / "run"
    assert main(["run", str(root / "images"), "--poses", str(root / "transforms.json"), "--out", str(run),
                 "--export-mode", "copy", *FAST]) == 0
    rec = json.loads((run / "sfm" / "images.json").read_text())
    assert not any("secret" in (r.get("original") or "") and r["status"] == "kept" for r in rec["photos"])
    _no_secret_exported(run)
    (root / "images" / "img_06.png").unlink()
    (root / "images" / "img_06.png").symlink_to(_text_secret(tmp_path))
    assert main(["run", str(root / "images"), "--poses", str(root / "transforms.json"), "--out",
                 str(tmp_path / "run2"), *FAST]) == 2
    err = one_line_error(capsys)
    assert "transforms.json: the pose of 'images/img_06.png' names" in err and "a link that leads to" in err


def test_a_bare_colmap_model_never_finds_its_photos_in_the_working_directory(tmp_path, capsys, monkeypatch):
    """Its image names were looked up in the working directory (how the sweep's /etc/passwd got in); now a model
    with no photo folder given and none beside it is cameras without photos, and a stage that needs the photos
    says how to give them."""
    root, bare = capture(tmp_path / "cap")
    model = tmp_path / "model"
    shutil.copytree(root / "sparse" / "0", model)
    monkeypatch.chdir(root / "images")                    # the photos are here, under the model's names
    run = tmp_path / "run"
    assert main(["run", "--poses", str(model), "--out", str(run), *FAST]) == 2
    err = one_line_error(capsys)
    assert "images.json: no photo was found for the pose of 'img_" in err and "curate run PHOTOS --poses" in err
    assert not (run / "export" / "images").exists()
    assert main(["run", str(root / "images"), "--poses", str(model), "--out", str(tmp_path / "run2"), *FAST]) == 0


# ------------------------------------------------------------------ poses checked as cameras (issue 61, item 5)
def _frame(k, v, which=2):
    def m(d):
        d["frames"][which][k] = v
    return m


def _angle(a):
    """The focal length given as a field of view only: camera_angle_x = ``a``."""
    def m(d):
        for f in [d] + d["frames"]:
            f.pop("fl_x", None)
            f.pop("fl_y", None)
        d["camera_angle_x"] = a
    return m


def _centre(x):
    def m(d):
        d["frames"][4]["transform_matrix"][0][3] = x
    return m


def _nan_pose(d):
    d["frames"][5]["transform_matrix"][1][1] = float("nan")


TRANSFORMS_NOT_A_CAMERA = {            # the sweep's cases: each exported a wrong result or failed later unnamed
    "camera_angle_x = pi": (_angle(np.pi), "camera_angle_x", None),
    "camera_angle_x = 0": (_angle(0.0), "camera_angle_x", None),
    "fl_x tiny": (_frame("fl_x", 1e-3), "fl_x", 2),
    "k1 = 1e10": (_frame("k1", 1e10), "k1 k2", 2),
    "k1 = NaN": (_frame("k1", float("nan")), "k1 k2 p1 p2", 2),
    "a centre at 1e300": (_centre(1e300), "transform_matrix", 4),
    "a centre far from the others": (_centre(1e9), "transform_matrix", 4),
    "NaN c2w": (_nan_pose, "transform_matrix", 5),
}


@pytest.mark.parametrize("case", list(TRANSFORMS_NOT_A_CAMERA))
def test_a_transforms_json_pose_no_camera_has_is_one_line_naming_the_file_the_frame_and_the_field(
        tmp_path, capsys, case):
    """Issue 61: camera_angle_x = pi exported fl_x = 9.8e-15; k1 = 1e10 an all-black undistorted export; a camera at
    x = 1e300 numpy overflows and 9% coverage, all with exit 0; k1 = NaN failed only in the export without naming
    the pose file; camera_angle_x = 0 was an internal error. Each is refused at import, one line naming the file,
    the frame and the field, before anything is written."""
    root, _ = capture(tmp_path / "cap")
    tj = root / "transforms.json"
    d = json.loads(tj.read_text())
    for f in d["frames"]:          # per-frame intrinsics, as nerfstudio writes them, so one frame can be wrong
        f.update({k: d[k] for k in ("fl_x", "fl_y", "cx", "cy", "w", "h") if k in d})
    mutate, field, frame = TRANSFORMS_NOT_A_CAMERA[case]
    mutate(d)
    tj.write_text(json.dumps(d))
    run = tmp_path / "run"
    assert main(["run", str(root / "images"), "--poses", str(tj), "--out", str(run), *FAST]) == 2
    err = one_line_error(capsys)
    assert str(tj) in err and field in err and "internal error" not in err, err
    if frame is not None:
        assert f"frame {frame} ('images/img_{frame:02d}.png')" in err, err
    assert not run.exists()


def _camera_entry(k, v, i=3):
    def m(d):
        d["cameras"][i][k] = v
    return m


def _cameras_json_nan(d):
    d["cameras"][3]["c2w"][0][0] = float("nan")


@pytest.mark.parametrize("mutate, field", [(_camera_entry("fx", 0.0), "fx = 0.0"),
                                           (_cameras_json_nan, "c2w holds NaN"),
                                           (_camera_entry("width", -64), "width = -64")])
def test_a_cameras_json_value_no_camera_has_names_the_file_the_camera_and_the_field(tmp_path, capsys, mutate, field):
    """fx = 0, a NaN c2w, width < 0 in a cameras.json: the message named the field but not the file or the camera."""
    root, _ = capture(tmp_path / "cap")
    cj = root / "cameras.json"
    d = json.loads(cj.read_text())
    mutate(d)
    cj.write_text(json.dumps(d))
    assert main(["run", str(root / "images"), "--poses", str(cj), "--out", str(tmp_path / "run"), *FAST]) == 2
    err = one_line_error(capsys)
    assert str(cj) in err and "camera 3 ('images/img_03.png')" in err and field in err, err


def _colmap_text(root: Path, rec) -> Path:
    d = root / "text_model"
    d.mkdir()
    rec.write_text(str(d))
    return d


def _edit(path: Path, row: int, fn) -> None:
    """Apply ``fn`` to the words of the ``row``-th data line of a COLMAP text file."""
    lines = path.read_text().splitlines()
    rows = [k for k, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")]
    lines[rows[row]] = " ".join(fn(lines[rows[row]].split()))
    path.write_text("\n".join(lines) + "\n")


def _cut(name, keep):
    def m(model):
        p = model / name
        p.write_bytes(p.read_bytes()[:keep(len(p.read_bytes()))])
    return m


COLMAP_BROKEN = {   # (text model?, mutation, what the one line must say)
    "empty points3D.bin": (False, lambda m: (m / "points3D.bin").write_bytes(b""), "points3D.bin: empty"),
    "truncated images.bin": (False, _cut("images.bin", lambda n: n // 2), "images.bin: says it holds 12 images"),
    "truncated cameras.bin": (False, _cut("cameras.bin", lambda n: 10), "cameras.bin: says it holds 1 cameras"),
    "truncated points3D.bin": (False, _cut("points3D.bin", lambda n: 4), "points3D.bin: cut short"),
    "NaN quaternion": (True, lambda m: _edit(m / "images.txt", 2, lambda w: w[:1] + ["nan"] * 4 + w[5:]),
                       "images.txt: image 'img_02.png': its pose"),
    "duplicate names": (True, lambda m: _edit(m / "images.txt", 4, lambda w: w[:-1] + ["img_00.png"]),
                        "images.txt: 1 image name(s) appear more than once, e.g. 'img_00.png'"),
    "fx = 0": (True, lambda m: _edit(m / "cameras.txt", 0, lambda w: w[:4] + ["0"] + w[5:]),
               "fx of its camera in cameras.txt = 0.0 is not a usable value"),
    "width < 0": (True, lambda m: _edit(m / "cameras.txt", 0, lambda w: w[:2] + ["-64"] + w[3:]),
                  "cameras.txt: line 4: camera 1: WIDTH x HEIGHT = -64 x 48"),
}


@pytest.mark.parametrize("case", list(COLMAP_BROKEN))
def test_a_broken_colmap_model_is_one_line_naming_the_file_and_what_is_wrong(tmp_path, capsys, case):
    """Issue 61: COLMAP's reader said `std::bad_alloc` for an empty points3D.bin (curate then ended as if
    signalled), "unordered_map::at" for a truncated images.bin, its own source line for a NaN quaternion, and read
    a truncated cameras.bin on as zeros; duplicate names and fx = 0 were not named. Each is one line naming the
    file (and the line, image or byte) and what is wrong, exit 2, before COLMAP reads the model."""
    from curate.sfm.model import pycolmap_reconstruction
    root, _ = capture(tmp_path / "cap")
    text, mutate, said = COLMAP_BROKEN[case]
    model = _colmap_text(root, pycolmap_reconstruction(root / "sparse" / "0")) if text else root / "sparse" / "0"
    mutate(model)
    assert main(["run", str(root / "images"), "--poses", str(model), "--out", str(tmp_path / "run"), *FAST]) == 2
    err = one_line_error(capsys)
    assert f"{model}/" in err and said in err and "internal error" not in err, err


# ------------------------------------------------------------------ file names that are not UTF-8 (issue 61, item 6)
def test_a_photo_whose_name_is_not_utf8_is_skipped_and_listed_never_fatal(tmp_path, capsys):
    """One photo named in Latin-1 bytes (``caf\\xe9.png``) stopped the whole run with "'utf-8' codec can't encode
    character '\\udce9'": the import and SfM's ingest skip it, list it with why, and go on."""
    import shutil as sh
    from curate.sfm.config import SfmConfig
    from curate.sfm.ingest import ingest
    from curate.sfm.prep import input_key
    root, _ = capture(tmp_path / "cap")
    odd = os.path.join(os.fsencode(root / "images"), b"caf\xe9.png")
    sh.copyfile(root / "images" / "img_03.png", odd)
    run = tmp_path / "run"
    assert main(["run", str(root / "images"), "--poses", str(root / "transforms.json"), "--out", str(run), *FAST]) == 0
    recs = json.loads((run / "sfm" / "images.json").read_text())["photos"]
    said = [r for r in recs if r["rel"] == "caf\\xe9.png"]
    assert len(said) == 1 and said[0]["status"] == "skipped" and "not UTF-8" in said[0]["reason"], said
    assert "caf\\xe9.png" in (run / "report.html").read_text()
    assert len(json.loads((run / "sfm" / "cameras.json").read_text())["cameras"]) == 12
    input_key(SfmConfig(), root / "images")                       # SfM: the photos' key, then the ingest
    recs = ingest(root / "images", tmp_path / "work", 64, progress=False)
    said = [r for r in recs if r.rel == "caf\\xe9.png"]
    assert len(said) == 1 and said[0].status == "skipped" and "not UTF-8" in said[0].reason
    assert sum(r.status == "kept" for r in recs) == 12


def test_a_folder_of_links_to_photos_elsewhere_is_the_users_capture(tmp_path, capsys):
    """A batch or a dataset tool (DVC, git-annex) keeps photos as links into a store: a link that leads out of the
    folder to a photo is the folder's photo, with the photo folder given or not."""
    root, _ = capture(tmp_path / "store")
    links = tmp_path / "cap"
    (links / "images").mkdir(parents=True)
    for f in sorted((root / "images").iterdir()):
        (links / "images" / f.name).symlink_to(f)
    shutil.copy(root / "transforms.json", links / "transforms.json")
    for k, photos in enumerate(([], [str(links / "images")])):
        assert main(["run", *photos, "--poses", str(links / "transforms.json"), "--out", str(tmp_path / f"r{k}"),
                     *FAST]) == 0, capsys.readouterr().err
        assert len(load_sfm(tmp_path / f"r{k}").cameras) == 12
