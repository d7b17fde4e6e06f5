"""Export of the chosen subset: COLMAP model, transforms.json, file list, links or copies."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from curate.core.cameras import Cameras, look_at
from curate.core.transforms_json import read_transforms, write_transforms

from test_ingest import sha_tree

pycolmap = pytest.importorskip("pycolmap")
from curate.export.subset import ExportConfig, export_names, export_subset  # noqa: E402
from curate.sfm.config import SfmConfig  # noqa: E402
from curate.sfm.pose_import import import_poses, read_cameras  # noqa: E402


def ring(n: int, w: int = 64, h: int = 48) -> Cameras:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    c = np.stack([3 * np.cos(a), 3 * np.sin(a), 0.3 * np.sin(3 * a)], 1)
    return Cameras(look_at(c, np.zeros((n, 3))), 55.0, 56.0, w / 2 + 0.5, h / 2 - 0.25, w, h,
                   names=tuple(f"photos/img_{i:02d}.png" for i in range(n)))


def write_photos(folder: Path, cams: Cameras) -> None:
    from PIL import Image
    rng = np.random.default_rng(0)
    for i, n in enumerate(cams.names):
        p = folder / n
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.fromarray(rng.integers(0, 255, (int(cams.height[i]), int(cams.width[i]), 3), np.uint8)).save(p)


@pytest.fixture()
def import_run(tmp_path):
    """A run folder filled by import_poses from a generated transforms.json next to its photos."""
    cams = ring(12)
    src = tmp_path / "capture"
    write_photos(src, cams)
    write_transforms(src / "transforms.json", cams)
    run = tmp_path / "run"
    import_poses(SfmConfig(progress=False), src / "transforms.json", run)
    return cams, src, run


def test_export_round_trip_links(import_run, tmp_path):
    cams, src, run = import_run
    before = sha_tree(src)
    chosen = [cams.names[i] for i in (7, 2, 11, 0, 5)]
    out = export_subset(run, chosen, run / "export", mode="link")
    assert sha_tree(src) == before  # the photo folder is untouched
    names = [Path(n).name for n in chosen]
    # the file list, in the order chosen
    assert (out / "images.txt").read_text().split("\n")[:-1] == chosen
    # links resolve to the originals
    for n, c in zip(names, chosen):
        p = out / "images" / n
        assert p.is_symlink() and p.resolve() == (src / c).resolve()
    assert sorted(os.listdir(out / "images")) == sorted(names)
    # transforms.json: same poses and intrinsics, file paths inside the export
    ref = cams[[7, 2, 11, 0, 5]]
    back, files = read_transforms(out / "transforms.json", contained=False)   # links to the originals
    assert list(back.names) == [f"images/{n}" for n in names]
    assert all(Path(f).is_file() for f in files)
    for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height", "dist"):
        assert np.allclose(getattr(back, k), getattr(ref, k)), k
    # COLMAP model: only the chosen images, same poses (COLMAP's frame = the imported one)
    model, _ = read_cameras(out / "sparse" / "0")
    order = [list(model.names).index(n) for n in names]
    model = model[order]
    assert len(model) == 5 and list(model.names) == names
    assert np.allclose(model.c2w, ref.c2w, atol=1e-6)
    for k in ("fx", "fy", "cx", "cy", "width", "height"):
        assert np.allclose(getattr(model, k), getattr(ref, k)), k
    man = json.loads((out / "export.json").read_text())
    assert man["n_images"] == 5 and man["config"]["mode"] == "link"


def test_export_copy_mode_and_reexport(import_run):
    cams, src, run = import_run
    before = sha_tree(src)
    out = export_subset(run, list(cams.names[:5]), mode="link")
    assert out == (run / "export").resolve()
    out = export_subset(run, list(cams.names[3:6]), out, mode="copy")  # replaces the earlier export
    assert sha_tree(src) == before
    files = sorted((out / "images").iterdir())
    assert [p.name for p in files] == [Path(n).name for n in cams.names[3:6]]
    for p, n in zip(files, cams.names[3:6]):
        assert not p.is_symlink() and p.read_bytes() == (src / n).read_bytes()
    assert len(read_transforms(out / "transforms.json")[0]) == 3


def test_export_refuses_bad_input(import_run):
    cams, src, run = import_run
    with pytest.raises(ValueError, match="not registered"):
        export_subset(run, [cams.names[0], "nope.jpg"], run / "export")
    with pytest.raises(ValueError, match="repeated"):
        export_subset(run, [cams.names[0], cams.names[0]], run / "export")
    with pytest.raises(ValueError, match="photo folder"):
        export_subset(run, [cams.names[0]], src / "photos" / "export")
    with pytest.raises(ValueError, match="mode"):
        ExportConfig(mode="move")
    assert not (src / "photos" / "export").exists()


def test_export_names_unique():
    assert export_names(["/a/x.jpg", "/b/y.jpg"], ["x.jpg", "y.jpg"]) == ["x.jpg", "y.jpg"]
    assert export_names(["/p/a/x.jpg", "/p/b/x.jpg"], ["a/x.jpg", "b/x.jpg"]) == ["a__x.jpg", "b__x.jpg"]


def test_export_sfm_run_rescales_to_originals_and_filters_points(tmp_path):
    """An SfM-like run: working copies at half size, a model with points; the export describes the originals."""
    from curate.sfm.model import reconstruction_from_cameras
    from curate.sfm.prep import write_outputs

    orig = ring(8, 128, 96)
    photos = tmp_path / "photos"
    write_photos(photos, orig)
    work = orig.scaled_images(0.5)
    work = Cameras(work.c2w, work.fx, work.fy, work.cx, work.cy, work.width, work.height,
                   names=tuple(f"img_{i:02d}.jpg" for i in range(8)))
    rec = reconstruction_from_cameras(work)
    # points: each projected into every camera that sees it; keypoints added per image
    rng = np.random.default_rng(1)
    xyz = rng.uniform(-0.5, 0.5, (40, 3))
    uv, depth = work.project(xyz)  # [N, P, 2], [N, P]
    w, h = work.width[:, None], work.height[:, None]
    inside = (depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0) & (uv[..., 1] < h)
    seen_by = {}
    for i in range(len(work)):
        img = rec.image(i + 1)
        pts = np.nonzero(inside[i])[0]
        rec.images[i + 1].points2D = pycolmap.Point2DList([pycolmap.Point2D(uv[i, p]) for p in pts])
        for k, p in enumerate(pts):
            seen_by.setdefault(int(p), []).append(pycolmap.TrackElement(img.image_id, k))
    for p, els in seen_by.items():
        rec.add_point3D(xyz[p], pycolmap.Track(els), np.array([200, 10, 10], np.uint8))
    run = tmp_path / "run"
    out_sfm = run / "sfm"
    (out_sfm / "sparse" / "0").mkdir(parents=True)
    rec.write(out_sfm / "sparse" / "0")
    records = [{"original": str((photos / n).resolve()), "rel": Path(n).name, "status": "kept", "reason": "",
                "working": w, "orig_width": 128, "orig_height": 96, "width": 64, "height": 48,
                "scale_x": 0.5, "scale_y": 0.5, "format": "png", "orientation": 1}
               for n, w in zip(orig.names, work.names)]
    write_outputs(out_sfm, work, xyz, np.zeros((40, 3), np.uint8), np.zeros(40), records,
                  [f"images/{n}" for n in work.names], 1.0)
    (out_sfm / "stage.json").write_text(json.dumps({"photos": str(photos.resolve())}))

    chosen = ["img_03.jpg", "img_04.jpg", "img_05.jpg"]
    out = export_subset(run, chosen)
    back, _ = read_transforms(out / "transforms.json")
    ref = orig[[3, 4, 5]]
    for k in ("c2w", "fx", "fy", "cx", "cy", "width", "height"):
        assert np.allclose(getattr(back, k), getattr(ref, k)), k
    m = pycolmap.Reconstruction(out / "sparse" / "0")
    assert sorted(m.image(i).name for i in m.reg_image_ids()) == ["img_03.png", "img_04.png", "img_05.png"]
    cam = next(iter(m.cameras.values()))
    assert (cam.width, cam.height) == (128, 96) and np.allclose(cam.params, [55, 56, 64.5, 47.75])
    keep = {3, 4, 5}
    want = sum(sum(int(inside[i, p]) for i in keep) >= 2 for p in range(40))
    assert m.num_points3D() == want > 0
    assert m.compute_mean_reprojection_error() < 1e-6  # keypoints were rescaled with the cameras
    assert (out / "images.txt").read_text() == "img_03.png\nimg_04.png\nimg_05.png\n"
    with pytest.raises(ValueError, match="photo folder"):
        export_subset(run, chosen, photos / "sub")
    # connectivity of the subset through shared points, as a brute force over the projections counts it
    from curate.sfm.subset_model import covisible_groups, write_subset_model
    for min_shared in (1, 15, 10_000):
        got = write_subset_model(out_sfm / "sparse" / "0", chosen, tmp_path / f"m{min_shared}",
                                 min_shared=min_shared)["components"]
        kept_pts = [p for p in range(40) if sum(int(inside[i, p]) for i in keep) >= 2]
        edges = [(a, b) for a in keep for b in keep if a < b
                 and sum(int(inside[a, p] and inside[b, p]) for p in kept_pts) >= min_shared]
        assert got == covisible_groups(sorted(keep), edges)
    assert write_subset_model(out_sfm / "sparse" / "0", chosen, tmp_path / "mx", min_shared=10_000)["components"] \
        == [1, 1, 1]


def test_covisible_groups():
    from curate.sfm.subset_model import covisible_groups
    assert covisible_groups([1, 2, 3, 4, 5], [(1, 2), (2, 3), (4, 5)]) == [3, 2]
    assert covisible_groups([1, 2, 3], []) == [1, 1, 1]
    assert covisible_groups([], []) == []
    assert covisible_groups([7], [(7, 7)]) == [1]


def test_connectivity_warning():
    from curate.export.stage import connectivity_warning
    assert connectivity_warning({"n_points3D_source": 100, "components": [12]}) is None
    assert connectivity_warning({"n_points3D_source": 0, "components": [1] * 12}) is None   # poses without points
    w = connectivity_warning({"n_points3D_source": 100, "components": [9, 3]})
    assert "12 exported images form 2 groups" in w and "9, 3" in w


@pytest.mark.parametrize("first", ["link", "copy"])
def test_a_file_the_user_changed_in_the_export_is_never_removed(import_run, first):
    """Issue 49: an image editor's save replaces an exported link by a file (or rewrites a copied file), or the
    user edits transforms.json: a new export refuses, naming the file, and removes nothing; an untouched
    export (links, or copies equal to their originals) is replaced as before."""
    cams, src, run = import_run
    out = export_subset(run, list(cams.names[:4]), mode=first)
    export_subset(run, list(cams.names[1:5]), out, mode=first)          # untouched: replaced
    img = out / "images" / Path(cams.names[2]).name
    img.unlink()
    img.write_bytes(b"edited by the user")
    listing = sorted(p.name for p in (out / "images").iterdir())
    for mode in ("link", "copy"):
        with pytest.raises(ValueError, match=f"{img.name} was changed since curate exported it"):
            export_subset(run, list(cams.names[:3]), out, mode=mode)
        assert (img.read_bytes() == b"edited by the user"
                and sorted(p.name for p in (out / "images").iterdir()) == listing)
    img.unlink()                                                           # the user moved it out
    export_subset(run, list(cams.names[:3]), out, mode="copy")
    tj = out / "transforms.json"
    tj.write_text(tj.read_text().replace('"w"', '"w" ', 1))                # an edit of curate's own file
    with pytest.raises(ValueError, match="transforms.json was changed"):
        export_subset(run, list(cams.names[:2]), out, mode="copy")
    assert tj.is_file() and (out / "images" / Path(cams.names[0]).name).is_file()


def test_copies_are_checked_against_what_was_written_and_a_users_text_model_stays(import_run, tmp_path):
    """A copied export whose originals moved (the photo folder moved; the run resumes there) is not taken for
    an edit: each copy is checked against its own checksum. A text model the user converted into the export's
    sparse/0 (`colmap model_converter --output_type TXT`) is not curate's and stays through a new export."""
    import json
    import shutil
    cams, src, run = import_run
    out = export_subset(run, list(cams.names[:4]), tmp_path / "exp", mode="copy")
    rec = json.loads((out / "export.json").read_text())
    assert all(f"images/{Path(n).name}" in rec["files"] for n in cams.names[:4])
    moved = tmp_path / "moved_photos"
    shutil.move(str(src), str(moved))                                  # the originals are elsewhere now
    from curate.export.subset import _changed
    assert _changed(out, json.loads((out / "export.json").read_text())) is None   # no edit: nothing said
    (out / "sparse" / "0" / "points3D.txt").write_text("# the user's\n")
    shutil.move(str(moved), str(src))                                  # (the photos back: an export reads them)
    export_subset(run, list(cams.names[1:5]), out, mode="copy")
    assert (out / "sparse" / "0" / "points3D.txt").read_text() == "# the user's\n"
    img = out / "images" / Path(cams.names[2]).name
    img.write_bytes(b"edited by the user")
    with pytest.raises(ValueError, match=f"{img.name} was changed since curate exported it"):
        export_subset(run, list(cams.names[1:5]), out, mode="copy")
    assert img.read_bytes() == b"edited by the user"


@pytest.mark.slow
def test_curate_export_on_a_run_keeps_an_edited_image(tmp_path, capsys):
    """`curate export RUN --mode copy` after the user replaced an exported link by an edited file: a one-line
    error naming the file, exit 2, the file kept; `curate select RUN --budget 5` likewise."""
    from curate.cli import main
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    run = tmp_path / "run"
    assert main(["run", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--out", str(run),
                 "--budget", "8", "--no-evaluate", "--res", "12", "--triangulate", "off"]) == 0
    img = sorted((run / "export" / "images").iterdir())[3]
    img.unlink()
    img.write_bytes(b"edited")
    for argv in (["export", str(run), "--mode", "copy"], ["select", str(run), "--budget", "5"]):
        capsys.readouterr()
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert f"{img} was changed since curate" in err and "Traceback" not in err   # one guard, every stage
        assert img.read_bytes() == b"edited"
