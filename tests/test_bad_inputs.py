"""A careful user's bad inputs: every one is a one-line error (exit 2) that names the file or the
option, raised before any training, and every input file is byte-identical afterwards."""

from __future__ import annotations

import hashlib
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from curate import cli
from curate.core.transforms_json import write_transforms
from curate.core.transforms_json import read_transforms

SAMPLE = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
N = 16


def tree_hash(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """16 photos of the sample walk with their transforms.json (a good input to break)."""
    d = tmp_path_factory.mktemp("inputs")
    cams, files = read_transforms(SAMPLE / "transforms.json")
    (d / "images").mkdir()
    for f in files[:N]:
        shutil.copy2(f, d / "images" / Path(f).name)
    write_transforms(d / "transforms.json", cams[list(range(N))], [f"images/{Path(f).name}" for f in files[:N]])
    return d


def frames(good: Path) -> dict:
    return json.loads((good / "transforms.json").read_text())


def poses_case(name: str, mutate):
    """A transforms.json broken by ``mutate(meta)`` (or raw text when it returns a str)."""
    def make(good: Path, tmp: Path) -> Path:
        meta = frames(good)
        out = mutate(meta)
        p = good / f"bad_{name}.json"
        p.write_text(out if isinstance(out, str) else json.dumps(meta))
        return p
    return make


def _set(path, value):
    def f(meta):
        fr = meta["frames"][3]
        *head, last = path
        for k in head:
            fr = fr[k]
        fr[last] = value
    return f


def _matrix(fn):
    def f(meta):
        m = np.array(meta["frames"][3]["transform_matrix"], float)
        meta["frames"][3]["transform_matrix"] = fn(m).tolist()
    return f


def _shear(m):
    m = m.copy()
    m[0, :3] += 0.4 * m[1, :3]
    return m


def _del(key):
    def f(meta):
        for fr in meta["frames"]:
            fr.pop(key, None)
        meta.pop(key, None)
        if key == "fl_x":
            for k in ("fl_y", "camera_angle_x", "camera_angle_y"):
                meta.pop(k, None)
                for fr in meta["frames"]:
                    fr.pop(k, None)
    return f


def _dup(meta):
    meta["frames"][5]["file_path"] = meta["frames"][4]["file_path"]


def _fl(value):
    def f(meta):
        meta["frames"][3]["fl_x"] = value
    return f


POSES = {
    "empty": (lambda m: "", "not valid JSON"),
    "garbage": (lambda m: "{frames: oops", "not valid JSON"),
    "a_list": (lambda m: "[1, 2, 3]", "not a transforms.json"),
    "no_frames": (lambda m: m.pop("frames") and None, "frames"),
    "zero_frames": (lambda m: m.update(frames=[]), "frames"),
    "frame_not_object": (lambda m: m["frames"].__setitem__(3, 7), "frame 3"),
    "no_matrix": (lambda m: m["frames"][3].pop("transform_matrix") and None, "frame 3"),
    "matrix_shape": (_set(["transform_matrix"], [[1, 0], [0, 1]]), "frame 3"),
    "matrix_text": (_set(["transform_matrix"], "identity"), "frame 3"),
    "matrix_nan": (_matrix(lambda m: np.where(np.eye(4, dtype=bool), np.nan, m)), "NaN"),
    "matrix_inf": (_matrix(lambda m: np.where(np.arange(16).reshape(4, 4) == 3, np.inf, m)), "frame 3"),
    "rotation_scaled": (_matrix(lambda m: np.vstack([np.hstack([3 * m[:3, :3], m[:3, 3:]]), m[3:]])), "orthonormal"),
    "rotation_sheared": (_matrix(_shear), "orthonormal"),
    "reflection": (_matrix(lambda m: m @ np.diag([1.0, 1.0, -1.0, 1.0])), "reflection"),
    "bottom_row": (_matrix(lambda m: np.vstack([m[:3], [0, 0, 0, 2]])), "bottom row"),
    "focal_zero": (_fl(0.0), "fl_x"),
    "focal_negative": (_fl(-50.0), "fl_x"),
    "focal_text": (_fl("wide"), "frame 3"),
    "no_intrinsics": (_del("fl_x"), "fl_x"),
    "duplicate_files": (_dup, "more than one frame"),
    "nested_deep": (lambda m: "[" * 100000 + "]" * 100000, "nested too deeply"),
    "camera_fisheye": (lambda m: m.update(camera_model="OPENCV_FISHEYE"), "camera_model 'OPENCV_FISHEYE'"),
    "camera_unknown": (_set(["camera_model"], "FISHEYE_9000"), "camera_model 'FISHEYE_9000'"),
}
COMMANDS = {
    "score": lambda p, out: ["score", str(p), "--res", "8"],
    "select": lambda p, out: ["select", str(p), "--budget", "4", "--res", "8", "--out", str(out)],
    "sfm": lambda p, out: ["sfm", "--poses", str(p), "--out", str(out)],
    "run": lambda p, out: ["run", "--poses", str(p), "--out", str(out), "--budget", "4", "--iters", "2",
                           "--folds", "2"],
}


def check(argv, capsys, msg, inputs: Path) -> str:
    before = tree_hash(inputs)
    code = cli.main(argv)
    err = capsys.readouterr().err
    last = err.strip().splitlines()[-1] if err.strip() else ""
    assert code == 2, f"exit {code}: {err}"
    assert "Traceback" not in err and last.startswith("curate "), err
    assert msg.lower() in last.lower(), last
    assert tree_hash(inputs) == before
    return last


@pytest.mark.parametrize("case", sorted(POSES))
@pytest.mark.parametrize("cmd", sorted(COMMANDS))
def test_bad_poses_are_one_line_errors_naming_the_file(good, tmp_path, capsys, case, cmd):
    mutate, msg = POSES[case]
    p = poses_case(case, mutate)(good, tmp_path)
    try:
        last = check(COMMANDS[cmd](p, tmp_path / "out"), capsys, msg, good)
        assert p.name in last
    finally:
        p.unlink()


OPTIONS = [
    (["--budget", "0"], "at least 2"), (["--budget", "1"], "at least 2"), (["--budget", "-3"], "--budget"),
    (["--budget", "ten"], "--budget"), (["--budget", "0%"], "--budget"), (["--budget", "150%"], "--budget"),
    (["--budget", "16"], "all 16 registered photos"), (["--budget", "400"], "all 16 registered photos"),
    (["--budget", "100%"], "all 16 registered photos"),
    (["--iters", "0"], "--iters"), (["--iters", "-5"], "--iters"), (["--iters", "many"], "--iters"),
    (["--holdout-every", "0"], "--holdout-every"), (["--holdout-every", "1"], "--holdout-every"),
    (["--eval-size", "0"], "--eval-size"), (["--random-seeds", "-1"], "--random-seeds"),
    (["--workers", "-2"], "--workers"), (["--gamma", "-1"], "gamma"), (["--gamma", "1000"], "gamma"),
    (["--gamma", "nan"], "gamma"), (["--box=0,0,0,1,1"], "six numbers"), (["--box=0,0,0,inf,1,1"], "finite"),
    (["--box=0,0,0,nan,1,1"], "finite"), (["--box=1,0,0,0,1,1"], "max"), (["--bins", "0x10"], "--bins"),
    (["--bins", "ax3"], "--bins"), (["--res", "0"], "res"), (["--device", "gpu9"], "--device"),
    (["--device", "cuda"], "--device"), (["--method", "best"], "--method"),
    (["--export-mode", "move"], "--export-mode"), (["--bins", "99999999999x2"], "--bins"),
    (["--matcher", "magic"], "--matcher"), (["--max-size", "8"], "--max-size"),
    (["--budget", "-5%"], "--budget"), (["--sift-peak-threshold", "-1"], "--sift-peak-threshold"),
    (["--sift-peak-threshold", "2"], "--sift-peak-threshold"),
    (["--sift-upsample-below", "-1"], "--sift-upsample-below"), (["--eval-minutes", "-1"], "--eval-minutes"),
    (["--folds", "-2"], "--folds"), (["--equivalence-db", "0"], "--equivalence-db"),
]


@pytest.mark.parametrize("extra, msg", OPTIONS, ids=[" ".join(a) for a, _ in OPTIONS])
def test_bad_options_fail_before_any_training(good, tmp_path, capsys, extra, msg):
    argv = ["run", str(good / "images"), "--poses", str(good / "transforms.json"), "--out", str(tmp_path / "out"),
            "--budget", "4", "--iters", "2", "--folds", "2", *extra]
    check(argv, capsys, msg, good)
    assert not list((tmp_path / "out").glob("evaluate/*/stage.json")) and not (tmp_path / "out" / "occupancy" /
                                                                                "field.pt").exists()


def test_folders_given_wrong(good, tmp_path, capsys):
    """--out a file, a user's folder, inside the photos; photos inside --out; nothing to read."""
    f = tmp_path / "afile"
    f.write_text("x")
    users = tmp_path / "mine"
    users.mkdir()
    (users / "notes.txt").write_text("keep me")
    empty = tmp_path / "empty"
    empty.mkdir()
    cases = [
        (["run", str(good / "images"), "--poses", str(good / "transforms.json"), "--out", str(f)], "a file"),
        (["run", str(good / "images"), "--poses", str(good / "transforms.json"), "--out", str(users)],
         "did not create"),
        (["run", str(good / "images"), "--poses", str(good / "transforms.json"), "--out", str(good / "images" / "r")],
         "inside the photo folder"),
        (["run", str(good / "images"), "--poses", str(good / "transforms.json"), "--out", str(good)], "inside the run"),
        (["sfm", str(tmp_path / "nope"), "--out", str(tmp_path / "o1")], "nope"),
        (["sfm", str(empty), "--out", str(tmp_path / "o2")], "usable photos"),
        (["run", "--out", str(tmp_path / "o3")], "photo folder"),
        (["score", str(tmp_path / "missing.json")], "no such file"),
        (["score", str(empty)], "without a COLMAP model"),
        (["select", str(good / "transforms.json"), "--out", str(tmp_path / "o4")], "--budget is required"),
        (["select", str(good / "transforms.json"), "--budget", "4"], "--out is required"),
        (["occupancy", str(empty)], "run.json"),
        (["report", str(tmp_path / "nope")], "no such run folder"),
        (["evaluate", str(users)], "run.json"),
        (["batch", "--out", str(tmp_path / "o5")], "folders"),
        (["batch", "--list", str(tmp_path / "nolist.txt"), "--out", str(tmp_path / "o6")], "--list"),
    ]
    before_users = tree_hash(users)
    for argv, msg in cases:
        check(argv, capsys, msg, good)
    assert tree_hash(users) == before_users and f.read_text() == "x"
    assert len(cases) >= 16


def test_unreadable_photos_of_a_pose_import_are_skipped_and_listed_before_any_training(good, tmp_path, capsys):
    """Truncated, empty, non-image files and a dangling link: skipped with the reason in images.json,
    their cameras dropped, the rest imported; an image of another aspect is an error naming it."""
    d = tmp_path / "cap"
    shutil.copytree(good, d)
    imgs = sorted((d / "images").iterdir())
    data = imgs[1].read_bytes()
    imgs[1].write_bytes(data[: len(data) // 3])                       # truncated
    imgs[2].write_bytes(b"")                                           # empty
    imgs[3].write_text("not a picture")                                # text named .jpg
    imgs[4].unlink()
    imgs[4].symlink_to(tmp_path / "gone.jpg")                          # dangling link
    before = tree_hash(d)
    assert cli.main(["sfm", "--poses", str(d / "transforms.json"), "--out", str(tmp_path / "run")]) == 0
    rec = json.loads((tmp_path / "run" / "sfm" / "images.json").read_text())
    skipped = {Path(r["original"]).name: r["reason"] for r in rec["photos"] if r["status"] == "skipped"}
    assert set(skipped) == {imgs[i].name for i in (1, 2, 3, 4)} and all(skipped.values())
    assert "missing" in skipped[imgs[4].name] and "empty" in skipped[imgs[2].name]
    cams = json.loads((tmp_path / "run" / "sfm" / "cameras.json").read_text())["cameras"]
    assert len(cams) == N - 4
    assert tree_hash(d) == before
    # a photo turned sideways (another aspect than its pose's camera): an error naming it
    from PIL import Image
    im = Image.open(imgs[6])
    im.transpose(Image.Transpose.ROTATE_90).save(imgs[6])
    last = check(["sfm", "--poses", str(d / "transforms.json"), "--out", str(tmp_path / "run2")], capsys,
                 "another aspect", d)
    assert imgs[6].name in last


def test_the_field_decodes_16_bit_grey_and_exif_rotation_like_ingest(tmp_path):
    """The --poses path's loader and SfM ingest decode alike: a 16-bit grey TIFF is mid-grey, not
    white; an EXIF-rotated JPEG is upright."""
    from PIL import Image
    from curate.field.train import load_image
    from curate.core.images import read_image
    a = np.full((30, 40), 32768, np.uint16)
    Image.fromarray(a).save(tmp_path / "grey16.tif")
    got = load_image(tmp_path / "grey16.tif", 40, 30)
    assert np.allclose(got, 0.5, atol=0.01)
    assert np.allclose(read_image(tmp_path / "grey16.tif")[0] / 255.0, got, atol=1 / 255)
    rgb = np.zeros((30, 40, 3), np.uint8)
    rgb[:, :20] = 255                                                   # left half white
    im = Image.fromarray(rgb).transpose(Image.Transpose.ROTATE_90)      # stored sideways, 30 wide 40 high
    exif = Image.Exif()
    exif[0x0112] = 6                                                    # "turn 90 deg clockwise to view": upright 40x30
    im.save(tmp_path / "rot.jpg", exif=exif.tobytes(), quality=95)
    up = load_image(tmp_path / "rot.jpg", 40, 30)
    ref = read_image(tmp_path / "rot.jpg")[0]
    assert ref.shape == (30, 40, 3) and up.shape == (30, 40, 3)
    assert up[:, :15].mean() > 0.9 and up[:, 25:].mean() < 0.1        # the white half where it belongs
    assert np.abs(up - ref / 255.0).max() < 0.05                       # as SfM ingest decodes it


def test_videos_given_wrong_are_one_line_errors_naming_the_file(good, tmp_path, capsys):
    """An audio-only .mp4, a video whose camera never moved, --max-frames 0 with a video: one line each,
    naming the file (or only the user's flag); --max-frames 0 does not fail a run without a video."""
    from test_video import walk_frames, write_audio_only, write_video
    d = tmp_path / "videos"
    d.mkdir()
    voice = write_audio_only(d / "voice.mp4")
    still = write_video(d / "still.mp4", walk_frames(1, 5) * 20)
    walk = write_video(d / "walk.mp4", walk_frames(6, 0))
    last = check(["sfm", str(voice), "--out", str(tmp_path / "o1")], capsys, "no video stream", d)
    assert str(voice) in last and "only audio" in last and "IndexError" not in last
    last = check(["sfm", str(still), "--out", str(tmp_path / "o2")], capsys, "the camera never moved", d)
    assert str(still) in last and "1 candidate frame of 20" in last and "usable photos" not in last
    last = check(["sfm", str(walk), "--out", str(tmp_path / "o3"), "--max-frames", "0"], capsys, "--max-frames", d)
    assert "change_step" not in last and "static_change" not in last and "got 0" in last
    assert cli.main(["sfm", "--poses", str(good / "transforms.json"), "--out", str(tmp_path / "o4"),
                     "--max-frames", "0"]) == 0                                  # no video: nothing to check


def test_an_unsupported_camera_model_is_one_warning_per_run(good, tmp_path, caplog):
    """A COLMAP model with fisheye cameras is imported through their pinhole part, said once for the
    whole run (with the count of images), not once per image."""
    import pycolmap
    from curate.sfm.model import reconstruction_from_cameras
    cams, files = read_transforms(good / "transforms.json")
    cams = type(cams)(cams.c2w, cams.fx, cams.fy, cams.cx, cams.cy, cams.width, cams.height, cams.dist,
                      tuple(Path(f).name for f in files))
    rec = reconstruction_from_cameras(cams)
    for cid, cam in list(rec.cameras.items()):
        p = cam.params
        rec.cameras[cid] = pycolmap.Camera(camera_id=cid, model="OPENCV_FISHEYE", width=cam.width, height=cam.height,
                                           params=[p[0], p[1], p[2], p[3], 0.01, 0.0, 0.0, 0.0])
    model = tmp_path / "model"
    model.mkdir()
    rec.write(str(model))
    with caplog.at_level("WARNING"):
        assert cli.main(["run", str(good / "images"), "--poses", str(model), "--out", str(tmp_path / "run"),
                         "--budget", "4", "--no-evaluate"]) == 0
    lines = [r.getMessage() for r in caplog.records if "pinhole part only" in r.getMessage()]
    assert len(lines) == 1 and lines[0].startswith(f"{N} of {N} images") and "OPENCV_FISHEYE" in lines[0], lines


def test_the_suite_covers_a_hundred_cases():
    n = len(POSES) * len(COMMANDS) + len(OPTIONS) + 16 + 2
    assert n >= 100


def test_a_disk_too_full_for_colmaps_database_is_a_one_line_error_before_it(tmp_path, capsys, monkeypatch):
    """Issue 49: COLMAP's SQLite aborts the whole process on a full disk (exit 134, a native trace): curate
    checks the free space its database needs before extracting features, and says so in one line."""
    import shutil
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk" / "images"
    photos = tmp_path / "photos"
    photos.mkdir()
    for p in sorted(sample.iterdir())[:6]:
        shutil.copy(p, photos / p.name)
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage._replace(free=10 << 20))
    before = tree_hash(photos)
    assert cli.main(["sfm", str(photos), "--out", str(tmp_path / "run")]) == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("curate sfm: error: not enough free space") and "MB are free" in last
    assert (not (tmp_path / "run" / "sfm" / "stage.json").exists()
            and not (tmp_path / "run" / "sfm" / "database.db").exists())
    assert tree_hash(photos) == before


def test_a_full_disk_while_writing_is_a_one_line_error_naming_the_file(tmp_path, capsys, monkeypatch):
    """Issue 49: ENOSPC ended in "internal error: OSError: [Errno 28]"; it is one line naming the file being
    written, exit 2, and the file is not left half-written."""
    import errno
    from curate.core import stage
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    run = tmp_path / "run"
    assert cli.main(["run", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--out", str(run),
                     "--budget", "8", "--no-evaluate", "--res", "8", "--triangulate", "off"]) == 0
    real = stage.Path.write_text

    def full(self, text, *a, **k):
        if self.name.startswith("report.json"):
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, text, *a, **k)
    monkeypatch.setattr(stage.Path, "write_text", full)
    before = (run / "report.json").read_text()
    capsys.readouterr()
    assert cli.main(["report", str(run)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the disk is full" in err[0] and str(run / "report.json") in err[0]
    assert (run / "report.json").read_text() == before and not list(run.glob("report.json.tmp*"))


def test_the_databases_space_is_estimated_at_its_real_size_not_far_beyond():
    """The free-space check must not refuse a run on a roomy disk: the estimate is above the real databases of
    ../shared's sets and within a few times them (the drone flight, 75 photos matched exhaustively: 96 MB;
    the office walk, 373 sequentially: 77 MB)."""
    from curate.sfm.config import SfmConfig
    from curate.sfm.prep import database_bytes
    cfg = SfmConfig()
    assert 96e6 < database_bytes(75, "exhaustive", cfg) < 5 * 96e6      # photos with features near the cap
    assert 77e6 < database_bytes(373, "sequential", cfg) < 2**30        # small frames: fewer features than the cap
    assert database_bytes(1000, "exhaustive", cfg) < 10 * 2**30          # was 49 GB


def test_a_full_disk_while_a_training_saves_its_field_names_the_file(tmp_path, capsys, monkeypatch):
    """Issue 61: a full disk during the evaluation ended in torch's "[enforce fail at inline_container.cc:672]",
    an internal error; it is the one line of every full disk, naming the field being written, exit 2."""
    import errno
    import io
    from curate.field import model
    from test_export import ring, write_photos
    from curate.core.transforms_json import write_transforms
    cams = ring(12)
    write_photos(tmp_path / "cap", cams)
    write_transforms(tmp_path / "cap" / "transforms.json", cams)
    run = tmp_path / "run"
    assert cli.main(["run", str(tmp_path / "cap" / "photos"), "--poses", str(tmp_path / "cap" / "transforms.json"),
                     "--out", str(run), "--no-evaluate", "--budget", "4", "--res", "8", "--triangulate", "off",
                     "--method", "medoids"]) == 0

    class Full(io.BytesIO):
        def write(self, b):
            raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(model, "open", lambda p, mode="r": Full(), raising=False)
    capsys.readouterr()
    assert cli.main(["evaluate", str(run), "--folds", "1", "--workers", "1", "--iters", "5", "--eval-size", "16",
                     "--random-seeds", "1"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.startswith("curate ")]
    assert len(err) == 1 and "the disk is full" in err[0] and "field.pt" in err[0] and str(run / "evaluate") in err[0]
    assert "inline_container" not in err[0]


def test_a_colmap_model_cut_short_by_a_full_disk_is_an_error_not_an_empty_model(tmp_path, monkeypatch):
    """COLMAP's writer leaves empty cameras.bin and images.bin on a full disk and says nothing (an export without
    cameras, exit 0): the model is read back after writing, and one cut short is a full disk naming the folder."""
    import errno
    import shutil
    from test_export import ring
    from curate.sfm.model import reconstruction_from_cameras, write_model
    rec = reconstruction_from_cameras(ring(5))
    write_model(rec, tmp_path / "ok")                                   # a whole model: read back, nothing said

    class CutShort:
        def write_binary(self, path):
            rec.write_binary(path)
            for f in ("cameras.bin", "images.bin"):
                (Path(path) / f).write_bytes(b"")
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage._replace(free=0))
    with pytest.raises(OSError) as e:
        write_model(CutShort(), tmp_path / "full")
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(tmp_path / "full")


def test_a_full_disk_when_the_run_folder_is_claimed_or_locked_names_it_and_blocks_nothing(tmp_path, capsys,
                                                                                          monkeypatch):
    """A full disk while curate marks a new run folder left a half-written marker that made the next run, once space
    was freed, refuse the folder as one curate did not create; while it writes the lock, it said only "no space
    left writing a file". Both name the file, leave nothing, and the same command then works."""
    import errno
    from curate.core import runfolder
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    argv = ["run", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--budget", "4",
            "--no-evaluate", "--res", "8", "--triangulate", "off", "--method", "medoids"]
    real_write, real_pwrite = runfolder.Path.write_text, runfolder.os.pwrite

    def full(self, *a, **k):
        if runfolder.MARKER in self.name:
            real_write(self, "{")                       # the disk fills half-way through the marker
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_write(self, *a, **k)
    monkeypatch.setattr(runfolder.Path, "write_text", full)
    run = tmp_path / "new" / "run"
    assert cli.main([*argv, "--out", str(run)]) == 2
    err = capsys.readouterr().err
    assert "the disk is full" in err and str(run) in err and not (tmp_path / "new").exists()
    monkeypatch.setattr(runfolder.Path, "write_text", real_write)
    monkeypatch.setattr(runfolder.os, "pwrite", lambda *a: (_ for _ in ()).throw(OSError(errno.ENOSPC, "full")))
    assert cli.main([*argv, "--out", str(run)]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ": error:" in ln]
    assert len(err) == 1 and "the disk is full" in err[0] and str(run / runfolder.LOCK) in err[0], err
    monkeypatch.setattr(runfolder.os, "pwrite", real_pwrite)
    assert cli.main([*argv, "--out", str(run)]) == 0
