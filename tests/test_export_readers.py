"""Issue 50: the export loads as it is in the readers the trainers use, and travels alone.

* :func:`read_like_3dgs`: the rules of the reference 3D Gaussian splatting loader (``readColmapSceneInfo`` /
  ``readColmapCameras``): ``sparse/0`` binary model, SIMPLE_PINHOLE or PINHOLE cameras only (any other model stops
  it), the field of view from the camera's focal length and size (the principal point is taken to be the image
  centre), each image opened from ``images/<name>``, the initial points from ``points3D.bin``;
* :func:`read_like_nerfstudio`: the nerfstudio data parser's (``transforms.json``: ``camera_model``, intrinsics at
  the top or per frame, ``file_path`` and ``ply_file_path`` relative to the data folder, ``images_F`` for
  ``--downscale-factor F``), the PLY read with open3d as nerfstudio reads it;
* pycolmap: the model's points project onto their keypoints in the exported images.

Run for a capture with lens distortion (an SfM-like run whose OPENCV camera has k1 = -0.12), for known poses and
for the sample's photos with known poses end to end.
"""

from __future__ import annotations

import json
import os
import tarfile
from pathlib import Path

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at

pycolmap = pytest.importorskip("pycolmap")
from curate.export.config import ExportConfig  # noqa: E402
from curate.export.subset import export_subset  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"


def read_like_3dgs(export: Path) -> list[dict]:
    """The cameras the reference 3DGS loader builds from ``export`` (AssertionError where it stops)."""
    from PIL import Image
    rec = pycolmap.Reconstruction(str(export / "sparse" / "0"))
    assert (export / "sparse" / "0" / "images.bin").is_file() and (export / "sparse" / "0" / "cameras.bin").is_file()
    out = []
    for im in rec.images.values():
        cam = rec.camera(im.camera_id)
        assert cam.model_name in ("SIMPLE_PINHOLE", "PINHOLE"), \
            "Colmap camera model not handled: only undistorted datasets (PINHOLE or SIMPLE_PINHOLE cameras) supported!"
        fx = cam.params[0]
        fy = cam.params[0] if cam.model_name == "SIMPLE_PINHOLE" else cam.params[1]
        path = export / "images" / im.name
        with Image.open(path) as img:                         # the loader opens each image by the model's name
            size = img.size
        out.append({"name": im.name, "fov_x": 2 * np.arctan(cam.width / (2 * fx)),
                    "fov_y": 2 * np.arctan(cam.height / (2 * fy)), "camera_size": (cam.width, cam.height),
                    "image_size": size, "principal": tuple(cam.principal_point_x_y()) if hasattr(
                        cam, "principal_point_x_y") else (cam.params[-2], cam.params[-1])})
    assert rec.num_points3D() > 0, "3DGS starts from the model's points"
    return out


def read_like_nerfstudio(export: Path, downscale: int = 1) -> list[dict]:
    """The frames nerfstudio's data parser reads from ``export/transforms.json``."""
    import open3d as o3d
    from PIL import Image
    meta = json.loads((export / "transforms.json").read_text())
    assert meta.get("camera_model", "OPENCV") in ("OPENCV", "PINHOLE", "OPENCV_FISHEYE", "EQUIRECTANGULAR")
    out = []
    for fr in meta["frames"]:
        get = lambda k: fr.get(k, meta.get(k))   # noqa: E731   (per frame, else the top level)
        rel = Path(fr["file_path"])
        if downscale > 1:
            rel = Path(f"{rel.parent}_{downscale}") / rel.name
        path = export / rel
        assert path.is_file() and not path.is_symlink(), path
        with Image.open(path) as img:
            size = img.size
        out.append({"path": path, "w": int(get("w")), "h": int(get("h")), "fl_x": float(get("fl_x")),
                    "cx": float(get("cx")), "cy": float(get("cy")), "k1": float(get("k1") or 0.0), "size": size})
    ply = export / meta["ply_file_path"]
    pc = o3d.io.read_point_cloud(str(ply))
    assert len(pc.points) > 0 and pc.has_colors()
    return out


def _check_export(export: Path, n_images: int, distorted_source: bool) -> None:
    cams = read_like_3dgs(export)
    assert len(cams) == n_images
    for c in cams:
        assert c["image_size"] == c["camera_size"], c             # the field of view belongs to this image
        if distorted_source:                                      # COLMAP's undistorter centres the principal point
            assert np.allclose(c["principal"], np.array(c["camera_size"]) / 2, atol=0.51)
    frames = read_like_nerfstudio(export)
    assert len(frames) == n_images
    for f in frames:
        assert f["size"] == (f["w"], f["h"]) and f["k1"] == 0.0
    rec = pycolmap.Reconstruction(str(export / "sparse" / "0"))
    assert rec.compute_mean_reprojection_error() < 0.5          # the points project onto their keypoints
    import open3d as o3d
    assert len(o3d.io.read_point_cloud(str(export / "sparse_pc.ply")).points) == rec.num_points3D()


@pytest.fixture()
def distorted_run(tmp_path):
    """A run folder as SfM leaves it for a camera with lens distortion: 10 photos (128 x 96) of a textured
    scene around the origin, an OPENCV camera (k1 = -0.12), 60 points observed at their distorted pixels."""
    from PIL import Image
    from curate.sfm.model import reconstruction_from_cameras
    from curate.sfm.prep import write_outputs
    n, w, h = 10, 128, 96
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([3 * np.cos(a), 3 * np.sin(a), 0.3 * np.sin(2 * a)], 1)
    dist = np.tile([-0.12, 0.01, 0.0, 0.0], (n, 1))
    cams = Cameras(look_at(c, np.zeros((n, 3))), 90.0, 90.0, w / 2, h / 2, w, h, dist=dist,   # COLMAP: cx, cy fixed
                   names=tuple(f"img_{i:02d}.jpg" for i in range(n)))
    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for name in cams.names:
        Image.fromarray(rng.integers(0, 255, (h, w, 3), np.uint8)).save(photos / name, quality=95)
    rec = reconstruction_from_cameras(cams)
    xyz = rng.uniform(-0.6, 0.6, (60, 3))
    tracks: dict[int, list] = {}
    for i in range(n):
        im = rec.image(i + 1)
        cam = rec.camera(im.camera_id)
        pc = (np.asarray(im.cam_from_world().matrix()) @ np.c_[xyz, np.ones(60)].T).T
        uv = np.asarray(cam.img_from_cam(pc))
        ok = np.flatnonzero((pc[:, 2] > 0) & (uv[:, 0] > 0) & (uv[:, 0] < w) & (uv[:, 1] > 0) & (uv[:, 1] < h))
        rec.images[i + 1].points2D = pycolmap.Point2DList([pycolmap.Point2D(uv[p]) for p in ok])
        for k, p in enumerate(ok):
            tracks.setdefault(int(p), []).append(pycolmap.TrackElement(im.image_id, k))
    for p, els in tracks.items():
        rec.add_point3D(xyz[p], pycolmap.Track(els), np.array([200, 120, 10], np.uint8))
    run = tmp_path / "run"
    (run / "sfm" / "sparse" / "0").mkdir(parents=True)
    rec.write(str(run / "sfm" / "sparse" / "0"))
    records = [{"original": str((photos / m).resolve()), "rel": m, "status": "kept", "reason": "", "working": m,
                "orig_width": w, "orig_height": h, "width": w, "height": h, "scale_x": 1.0, "scale_y": 1.0,
                "format": "jpeg", "orientation": 1} for m in cams.names]
    write_outputs(run / "sfm", cams, xyz, np.zeros((60, 3), np.uint8), np.zeros(60), records,
                  [f"images/{m}" for m in cams.names], 1.0)
    (run / "sfm" / "stage.json").write_text(json.dumps({"photos": str(photos.resolve())}))
    return cams, photos, run


def test_a_distorted_capture_exports_undistorted_pinhole_images_every_reader_loads(distorted_run):
    cams, photos, run = distorted_run
    chosen = list(cams.names[::2])
    before = {p.name: p.read_bytes() for p in photos.iterdir()}
    with pytest.raises(AssertionError, match="only undistorted datasets"):   # what 3DGS said of the old export
        export_subset(run, chosen, run / "old", config=ExportConfig(undistort="off"))
        read_like_3dgs(run / "old")
    out = export_subset(run, chosen)
    _check_export(out, len(chosen), distorted_source=True)
    assert {p.name: p.read_bytes() for p in photos.iterdir()} == before      # the originals untouched
    man = json.loads((out / "export.json").read_text())
    assert man["model"]["undistorted"] and man["model"]["camera_model"] == "PINHOLE"
    assert not (out / "distorted").exists() and not list(out.glob(".curate-undistort-*"))


def test_the_distorted_set_is_kept_on_request_and_a_re_export_removes_only_what_it_wrote(distorted_run):
    cams, photos, run = distorted_run
    chosen = list(cams.names[:4])
    out = export_subset(run, chosen, config=ExportConfig(keep_distorted=True, downscale=(2, 4)))
    kept = pycolmap.Reconstruction(str(out / "distorted" / "sparse" / "0"))
    assert {c.model_name for c in kept.cameras.values()} == {"OPENCV"}
    assert sorted(p.name for p in (out / "distorted" / "images").iterdir()) == chosen
    for f in (2, 4):                                            # nerfstudio's --downscale-factor F
        for fr in read_like_nerfstudio(out, downscale=f):
            assert fr["size"] == (fr["w"] // f, fr["h"] // f)
    (out / "notes.txt").write_text("mine")                     # the user's file beside the export
    out = export_subset(run, chosen[:2])                        # a smaller export, without the extras
    assert not (out / "distorted").exists() and not (out / "images_2").exists() and not (out / "images_4").exists()
    assert (out / "notes.txt").read_text() == "mine"
    _check_export(out, 2, distorted_source=True)


def test_the_default_export_travels_alone_by_tar_and_survives_its_run_folder(distorted_run, tmp_path):
    """No symbolic link into another folder: a tar of export/ alone, unpacked elsewhere after the run folder and
    the photos are gone, still loads in both readers."""
    cams, photos, run = distorted_run
    out = export_subset(run, list(cams.names[1::3]), config=ExportConfig(undistort="off"))
    assert not any(p.is_symlink() for p in out.rglob("*"))
    for p in (out / "images").iterdir():                      # hard links to the originals: no space taken
        assert os.stat(p).st_ino == os.stat(photos / p.name).st_ino
    tar = tmp_path / "export.tar"
    with tarfile.open(tar, "w") as t:
        t.add(out, arcname="export")
    import shutil
    shutil.rmtree(run)
    shutil.rmtree(photos)
    dest = tmp_path / "gpu"
    with tarfile.open(tar) as t:
        t.extractall(dest, filter="data")
    frames = read_like_nerfstudio(dest / "export")
    assert len(frames) == len(cams.names[1::3]) and all(f["k1"] != 0 for f in frames)   # distortion kept: OPENCV
    assert json.loads((dest / "export" / "transforms.json").read_text())["camera_model"] == "OPENCV"


@pytest.mark.slow
def test_the_samples_export_loads_in_every_reader(tmp_path):
    """The README's sample with known poses, end to end: the export loads as it is."""
    from curate.cli import main
    run = tmp_path / "run"
    assert main(["run", str(SAMPLE / "images"), "--poses", str(SAMPLE / "transforms.json"), "--out", str(run),
                 "--budget", "12", "--no-evaluate", "--downscale", "2"]) == 0
    n = len(json.loads((run / "select" / "selection.json").read_text())["chosen"])
    _check_export(run / "export", n, distorted_source=False)
    assert len(read_like_nerfstudio(run / "export", downscale=2)) == n


def test_undistorting_never_touches_the_users_files_beside_the_export(distorted_run, tmp_path):
    """A user's own files in the export folder (a photo in images/, a text model in sparse/0) stay as they are
    through an undistorted export, with or without the distorted set kept."""
    cams, photos, run = distorted_run
    out = tmp_path / "mine"
    (out / "images").mkdir(parents=True)
    (out / "sparse" / "0").mkdir(parents=True)
    (out / "images" / "notes.jpg").write_bytes(b"mine")
    (out / "sparse" / "0" / "cameras.txt").write_text("# mine\n")
    (out / "export.json").write_text(json.dumps({"images": [], "files": {}}))   # a record with nothing in it
    for keep in (False, True):
        export_subset(run, list(cams.names[:3]), out, config=ExportConfig(keep_distorted=keep))
        assert (out / "images" / "notes.jpg").read_bytes() == b"mine"
        assert (out / "sparse" / "0" / "cameras.txt").read_text() == "# mine\n"
        assert sorted(p.name for p in (out / "images").iterdir()) == ["img_00.jpg", "img_01.jpg", "img_02.jpg",
                                                                        "notes.jpg"]
