"""A run folder is curate's own: the user's files are never deleted or written over, one run
per folder at a time, and no worker outlives its run or writes into a folder its run lost.

Each of the data-loss cases a user reported is reproduced and must now be refused before
any work, with every input file byte-identical afterwards."""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from curate.cli import main
from curate.core import runfolder as rf

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data_samples" / "room_walk"
QUICK = ["--budget", "4", "--iters", "20", "--eval-size", "32", "--res", "8", "--random-seeds", "1", "--workers", "1",
         "--folds", "2", "--refine-iters", "20", "--refine-size", "32"]


def _env() -> dict:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}


def tree_hash(root: Path) -> dict[str, str]:
    """{relative path: sha256 of the content (a link: of its target's name)} of every entry under ``root``."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        if p.is_symlink():
            out[rel] = "link:" + os.readlink(p)
        elif p.is_file():
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
        else:
            out[rel] = "dir"
    return out


def project(dst: Path, n: int = 30) -> Path:
    """A small posed capture: the first ``n`` photos of the sample walk in ``dst/images`` and
    ``dst/transforms.json``."""
    tj = json.loads((SAMPLE / "transforms.json").read_text())
    tj["frames"] = tj["frames"][:n]
    (dst / "images").mkdir(parents=True)
    for f in tj["frames"]:
        shutil.copy2(SAMPLE / f["file_path"], dst / f["file_path"])
    (dst / "transforms.json").write_text(json.dumps(tj))
    return dst


# ------------------------------------------------------------------ (1) photos where a stage writes
@pytest.mark.parametrize("stage", ["export", "sfm", "occupancy", "select", "evaluate"])
def test_photos_living_in_a_stage_folder_of_out_are_refused_untouched(tmp_path, stage, capsys):
    proj = tmp_path / "proj"
    photos = project(proj / stage)
    (proj / "notes.txt").write_text("mine")
    before = tree_hash(tmp_path)
    # even adopting the folder: the inputs lie inside it
    rc = main(["run", str(photos), "--poses", str(photos / "transforms.json"), "--out", str(proj), "--adopt", *QUICK])
    err = capsys.readouterr().err
    assert rc == 2 and "inside the run folder" in err and str(photos) in err and str(proj) in err
    assert tree_hash(tmp_path) == before
    # the same through `curate sfm` and `curate select --out`
    assert main(["sfm", str(photos), "--poses", str(photos / "transforms.json"), "--out", str(proj)]) == 2
    assert main(["select", str(photos / "transforms.json"), "--budget", "3", "--out", str(photos)]) == 2
    assert tree_hash(tmp_path) == before


def test_input_inside_a_claimed_run_folder_and_run_folder_inside_the_photos(tmp_path):
    run = tmp_path / "run"
    rf.claim(run)
    inner = project(run / "mine")  # anywhere inside the run folder, not only in stage folders
    with pytest.raises(rf.RunFolderError, match="inside the run folder"):
        rf.claim(run, [inner, inner / "transforms.json"])
    with pytest.raises(rf.RunFolderError, match="inside the photo folder"):
        rf.claim(inner / "out", [inner])
    assert not (inner / "out").exists()
    # symbolic links are resolved: a link to the run folder is the run folder
    (tmp_path / "alias").symlink_to(run)
    with pytest.raises(rf.RunFolderError, match="inside the run folder"):
        rf.claim(tmp_path / "alias", [inner])


# ------------------------------------------------------------------ (2) an existing folder curate did not make
def _users_folder(d: Path) -> Path:
    for sub in ("sfm", "select", "export"):
        (d / sub).mkdir(parents=True)
        (d / sub / "keep.txt").write_text(f"user's {sub}")
    (d / "report.html").write_text("<p>my report</p>")
    (d / "run.json").write_text("{}")
    return d


def test_non_empty_folder_not_made_by_curate_is_refused_and_adoption_never_writes_over_it(tmp_path, capsys):
    out = _users_folder(tmp_path / "work")
    before = tree_hash(out)
    photos = project(tmp_path / "cap")
    args = [str(photos / "images"), "--poses", str(photos / "transforms.json"), "--out", str(out)]
    assert main(["run", *args, *QUICK]) == 2
    assert "curate did not create" in capsys.readouterr().err
    assert tree_hash(out) == before
    # adopted, curate would have to write over the user's sfm/, report.html, run.json: refused as well
    assert main(["run", *args, "--adopt", *QUICK]) == 2
    assert "never writes over it" in capsys.readouterr().err
    assert tree_hash(out) == before  # refused: not even curate's marker stays
    assert main(["sfm", *args]) == 2
    assert main(["report", str(out)]) == 2  # a stage command on a folder curate did not make
    assert tree_hash(out) == before


@pytest.mark.slow
def test_adopted_folder_keeps_every_file_of_the_user(tmp_path, capsys):
    out = tmp_path / "work"
    (out / "photos_backup").mkdir(parents=True)
    (out / "photos_backup" / "a.jpg").write_bytes(b"\xff\xd8 not really")
    (out / "notes.txt").write_text("mine")
    before = tree_hash(out)
    photos = project(tmp_path / "cap")
    args = ["run", str(photos / "images"), "--poses", str(photos / "transforms.json"), "--out", str(out), *QUICK,
            "--no-evaluate"]
    assert main(args) == 2  # not without --adopt
    assert main([*args, "--adopt"]) == 0, capsys.readouterr().err
    after = tree_hash(out)
    assert all(after[k] == v for k, v in before.items())
    assert (out / "report.json").is_file() and len(list((out / "export" / "images").iterdir())) == 4
    assert rf.read_marker(out)["adopted"] == ["notes.txt", "photos_backup"]
    # a second run with another budget redoes select and export, still without touching the user's files
    capsys.readouterr()
    assert main([*args[:-1], "--budget", "3"]) == 0, capsys.readouterr().err
    after = tree_hash(out)
    assert all(after[k] == v for k, v in before.items())
    assert len(list((out / "export" / "images").iterdir())) == 3


def test_a_file_dropped_into_a_finished_stage_is_never_cleared(tmp_path, capsys):
    photos = project(tmp_path / "cap")
    out = tmp_path / "run"
    args = ["run", str(photos / "images"), "--poses", str(photos / "transforms.json"), "--out", str(out), *QUICK,
            "--no-evaluate"]
    assert main(args) == 0
    (out / "export" / "images" / "my_edit.jpg").write_bytes(b"the user's")
    before = tree_hash(out / "export")
    capsys.readouterr()
    assert main([*args, "--budget", "3"]) == 2  # the export must be redone: refused, naming the file
    err = capsys.readouterr().err
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.strip() and "?chunk/s]" not in ln
             and "chunk/s]" not in ln]  # progress bars drawn before the refusal are not error lines
    assert "my_edit.jpg" in err and "did not write" in err and len(lines) == 1, lines
    assert tree_hash(out / "export") == before


# ------------------------------------------------------------------ a failed command leaves nothing behind
def _failures(tmp_path: Path, photos: Path, out: Path) -> dict[str, list[str]]:
    """Commands refused for a bad input (each after it claimed ``out``), by what is wrong."""
    tj, images = str(photos / "transforms.json"), str(photos / "images")
    (tmp_path / "broken.json").write_text("{frames: oops")
    return {
        "missing photo folder": ["run", str(tmp_path / "no_photos"), "--out", str(out), *QUICK],
        "missing photo folder (sfm)": ["sfm", str(tmp_path / "no_photos"), "--out", str(out)],
        "bad --poses": ["run", images, "--poses", str(tmp_path / "broken.json"), "--out", str(out), *QUICK],
        "missing --poses": ["sfm", "--poses", str(tmp_path / "none.json"), "--out", str(out)],
        "budget over the pool": ["select", tj, "--budget", "500", "--out", str(out)],
        "bad pose file (select)": ["select", str(tmp_path / "broken.json"), "--budget", "4", "--out", str(out)],
    }


def test_a_refused_command_leaves_no_run_folder(tmp_path, capsys):
    """A bad input found after --out was claimed: the new folder (and the parents curate made for it) is
    removed; no .curate-lock, .curate-run.json or run.json is left behind."""
    photos = project(tmp_path / "cap", n=6)
    for what, argv in _failures(tmp_path, photos, tmp_path / "new" / "deeper" / "out").items():
        assert main(argv) == 2, what
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.startswith("curate "), (what, err)
        assert not (tmp_path / "new").exists(), (what, sorted(p.name for p in (tmp_path / "new").rglob("*")))


def test_a_refused_command_leaves_an_existing_out_folder_as_it_was(tmp_path, capsys):
    """--out that was there (empty, or the user's and adopted) is left exactly as it was; one that is
    already a run folder keeps its marker."""
    photos = project(tmp_path / "cap", n=6)
    empty = tmp_path / "empty"
    empty.mkdir()
    users = _users_folder(tmp_path / "users")
    for what, argv in _failures(tmp_path, photos, empty).items():
        assert main(argv) == 2, what
        assert list(empty.iterdir()) == [], (what, [p.name for p in empty.iterdir()])
    before = tree_hash(users)
    for what, argv in _failures(tmp_path, photos, users).items():
        assert main([*argv, "--adopt"]) == 2, what
        assert tree_hash(users) == before, what
    run = rf.claim(tmp_path / "run")  # a run folder of curate's: its marker is not this command's to remove
    assert main(["sfm", "--poses", str(tmp_path / "none.json"), "--out", str(run)]) == 2
    assert rf.is_claimed(run)
    capsys.readouterr()


def test_a_stage_command_on_a_folder_that_is_not_a_run_folder_leaves_it_untouched(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    users = _users_folder(tmp_path / "users")
    before = tree_hash(users)
    for cmd in ("report", "occupancy", "evaluate", "export"):
        for folder in (empty, users):
            assert main([cmd, str(folder)]) == 2
            assert "not a run folder" in capsys.readouterr().err
        assert list(empty.iterdir()) == [] and tree_hash(users) == before
    assert main(["select", str(empty), "--budget", "4"]) == 2
    assert list(empty.iterdir()) == []
    capsys.readouterr()


def test_a_failed_command_keeps_a_folder_that_holds_more_than_bookkeeping(tmp_path, capsys):
    """A record the error points at (sfm/images.json of a folder without usable photos) stays, and so does
    the whole run folder; a stage that finished stays for the re-run to resume."""
    nothing = tmp_path / "nothing"
    nothing.mkdir()
    (nothing / "readme.txt").write_text("not a photo")
    out = tmp_path / "out"
    assert main(["sfm", str(nothing), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "usable photos" in err and str(out / "sfm" / "images.json") in err
    assert (out / "sfm" / "images.json").is_file() and rf.is_claimed(out)
    photos = project(tmp_path / "cap", n=6)
    run = tmp_path / "run"
    assert main(["run", str(photos / "images"), "--poses", str(photos / "transforms.json"), "--out", str(run),
                 *QUICK[2:], "--budget", "6", "--no-evaluate"]) == 2          # the whole pool: found after SfM
    assert "all 6 registered photos" in capsys.readouterr().err
    assert (run / "sfm" / "stage.json").is_file() and (run / "run.json").is_file()


def test_undo_claim_rules(tmp_path):
    """Only bookkeeping goes, and only what this claim made; a foreign file anywhere keeps everything."""
    for extra in ("sfm/colmap.log", "notes.txt", None):
        out = tmp_path / f"case_{extra is None}_{str(extra).replace('/', '_')}" / "run"
        with pytest.raises(RuntimeError):
            with rf.claimed(out):
                (out / "run.json").write_text("{}")
                (out / "sfm").mkdir()
                (out / "sfm" / rf.STAGE_MARKER).write_text("x")
                (out / "sfm" / "cameras.json.tmp123").write_text("x")
                if extra:
                    (out / extra).write_text("x")
                raise RuntimeError("boom")
        assert out.parent.exists() == (extra is not None)
        if extra:
            assert (out / extra).is_file() and rf.is_claimed(out)


# ------------------------------------------------------------------ clearing rules
def test_clear_tree_rules(tmp_path):
    from curate.core.stage import begin_stage, finish_stage
    loose = tmp_path / "loose" / "sfm"
    loose.mkdir(parents=True)
    (loose / "x.jpg").write_bytes(b"1")
    with pytest.raises(rf.RunFolderError, match="not inside a run folder"):
        begin_stage(loose, "k")  # never cleared outside a claimed run folder
    assert (loose / "x.jpg").read_bytes() == b"1"

    run = rf.claim(tmp_path / "run")
    d = run / "select"
    owns = ("*.json", "*.npz", "sub/*")
    assert begin_stage(d, "k1", owns=owns) is False
    (d / "a.json").write_text("{}")
    (d / "sub").mkdir()
    (d / "sub" / "b.bin").write_bytes(b"2")
    finish_stage(d, "k1", {}, time.perf_counter(), owns=owns)
    assert sorted(json.loads((d / "stage.json").read_text())["files"]) == ["a.json", "sub/b.bin"]
    assert begin_stage(d, "k1", owns=owns) is True  # fresh: untouched
    assert begin_stage(d, "k2", owns=owns) is False  # recorded files only: cleared
    assert sorted(p.name for p in d.iterdir()) == [rf.STAGE_MARKER]
    # killed half-way (marker, no record): what matches the stage's names is curate's scratch, cleared; the
    # user's own file is kept
    (d / "partial.npz").write_bytes(b"3")
    (d / "notes.txt").write_bytes(b"mine")
    assert begin_stage(d, "k3", owns=owns) is False and not (d / "partial.npz").exists()
    assert (d / "notes.txt").read_bytes() == b"mine"
    (d / "notes.txt").unlink()
    # a folder curate did not create (no marker, no record) inside a run folder: refused
    (run / "export").mkdir()
    (run / "export" / "photo.jpg").write_bytes(b"4")
    with pytest.raises(rf.RunFolderError, match="photo.jpg"):
        begin_stage(run / "export", "k")
    assert (run / "export" / "photo.jpg").read_bytes() == b"4"


def test_what_sqlite_leaves_beside_a_database_only_read_is_cleared_and_a_log_of_writes_is_kept(tmp_path):
    """A look into a finished run's database with a read-only SQLite reader leaves an empty write-ahead log and
    its index beside it: a re-run clears them (it refused to, naming database.db-wal). A log that holds writes
    is the user's change: refused, and kept."""
    import sqlite3
    from curate.core.stage import begin_stage, finish_stage
    run = rf.claim(tmp_path / "run")
    d = run / "sfm"
    owns = ("database.db", "database.db-*")
    assert begin_stage(d, "k1", owns=owns) is False
    con = sqlite3.connect(d / "database.db")
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT)")
    con.execute("INSERT INTO images VALUES (1, 'a.jpg')")
    con.commit()
    con.close()
    finish_stage(d, "k1", {}, time.perf_counter(), owns=owns)
    ro = sqlite3.connect(f"file:{d / 'database.db'}?mode=ro", uri=True)
    assert ro.execute("SELECT name FROM images").fetchall() == [("a.jpg",)]
    ro.close()
    assert sorted(p.name for p in d.iterdir() if p.name.startswith("database")) == [
        "database.db", "database.db-shm", "database.db-wal"]
    assert begin_stage(d, "k2", owns=owns) is False           # cleared, not refused
    assert not any(p.name.startswith("database") for p in d.iterdir())

    con = sqlite3.connect(d / "database.db")                 # a database written again, and recorded
    con.execute("PRAGMA journal_mode=WAL")
    con.execute("CREATE TABLE images (image_id INTEGER PRIMARY KEY, name TEXT)")
    con.commit()
    con.close()
    finish_stage(d, "k2", {}, time.perf_counter(), owns=owns)
    w = sqlite3.connect(d / "database.db")                   # the user writes; the log holds it while open
    w.execute("PRAGMA wal_autocheckpoint=0")
    w.execute("INSERT INTO images VALUES (2, 'mine.jpg')")
    w.commit()
    assert (d / "database.db-wal").stat().st_size > 0
    with pytest.raises(rf.RunFolderError, match="database.db-wal"):
        begin_stage(d, "k3", owns=owns)
    assert (d / "database.db-wal").stat().st_size > 0
    w.close()


def test_export_into_a_users_folder_never_clears_it(tmp_path):
    from curate.export.subset import export_subset
    from curate.sfm.pose_import import import_poses
    from curate.sfm.config import SfmConfig
    photos = project(tmp_path / "cap", n=6)
    run = rf.claim(tmp_path / "run")
    import_poses(SfmConfig(), photos / "transforms.json", run)
    names = json.loads((run / "sfm" / "cameras.json").read_text())["cameras"]
    names = [c["name"] for c in names][:3]
    mine = tmp_path / "mine"
    (mine / "images").mkdir(parents=True)
    (mine / "images" / "holiday.jpg").write_bytes(b"mine")
    before = tree_hash(mine)
    with pytest.raises(ValueError, match="not written by a curate export"):
        export_subset(run, names, mine)
    assert tree_hash(mine) == before
    # a re-export over an earlier export removes only what that export listed
    out = tmp_path / "exp"
    export_subset(run, names, out)
    (out / "images" / "extra.jpg").write_bytes(b"user")
    export_subset(run, names[:2], out)
    assert sorted(p.name for p in (out / "images").iterdir()) == sorted([Path(n).name for n in names[:2]] +
                                                                       ["extra.jpg"])
    assert (out / "images" / "extra.jpg").read_bytes() == b"user"


def test_unwritable_run_folder_is_a_one_line_error(tmp_path, capsys):
    photos = project(tmp_path / "cap", n=4)
    assert main(["sfm", "--poses", str(photos / "transforms.json"), "--out", "/proc/curate-run"]) == 2
    err = capsys.readouterr().err
    assert "cannot create the run folder /proc/curate-run" in err and len(err.strip().splitlines()) == 1
    if os.geteuid() != 0:  # root writes anywhere
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o555)
        with pytest.raises(rf.RunFolderError, match="cannot write"):
            rf.claim(ro)


# ------------------------------------------------------------------ (4) the lock
HOLD = ("import sys, time; from curate.core.runfolder import claimed\n"
        "with claimed(sys.argv[1]):\n    print('held', flush=True); time.sleep(60)\n")


def test_second_process_is_refused_naming_the_holder_and_a_dead_holder_is_taken_over(tmp_path, capsys, caplog):
    run = tmp_path / "run"
    p = subprocess.Popen([sys.executable, "-c", HOLD, str(run)], env=_env(), stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "held"
        with pytest.raises(rf.RunFolderBusy, match=rf"is in use by .*PID {p.pid}, started \d\d:\d\d:\d\d"):
            with rf.claimed(run):
                pass
        assert main(["report", str(run)]) == 2
        err = capsys.readouterr().err
        assert f"PID {p.pid}" in err and "in use" in err
    finally:
        p.kill()
        p.wait()
    with caplog.at_level(logging.WARNING, logger="curate.core.runfolder"):
        with rf.claimed(run):  # the holder died (SIGKILL): its lock is taken over
            assert rf.read_lock(run)["pid"] == os.getpid()
    assert f"PID {p.pid}" in caplog.text and "no longer running" in caplog.text
    assert rf.read_lock(run) == {}  # released on exit


def test_stale_lock_records_are_taken_over(tmp_path, caplog):
    run = rf.claim(tmp_path / "run")
    me = {"pid": os.getpid(), "start_time": rf.proc_start_time(os.getpid()), "host": os.uname().nodename}
    assert rf.holder_alive(me)
    assert not rf.holder_alive({**me, "start_time": me["start_time"] + 1})  # a reused PID is not the holder
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    dead_pid = int(dead.stdout)
    assert not rf.holder_alive({**me, "pid": dead_pid})
    for rec in ({**me, "pid": dead_pid, "token": "old"}, {**me, "pid": os.getppid(), "start_time": 1, "token": "old"}):
        (run / rf.LOCK).write_text(json.dumps(rec))
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger="curate.core.runfolder"):
            with rf.claimed(run):
                info = rf.read_lock(run)
                assert info["pid"] == os.getpid() and info["token"] != "old"
        assert f"PID {rec['pid']}" in caplog.text


def test_a_worker_whose_run_lost_the_lock_does_not_write_its_unit(tmp_path):
    from curate.evaluate.units import EvalConfig, Unit, eval_cameras, train_unit
    from curate.field.train import default_box
    from curate.sfm.io import image_paths
    from curate.sfm.pose_import import import_poses
    from curate.sfm.config import SfmConfig
    from curate.sfm.io import load_sfm
    photos = project(tmp_path / "cap", n=12)
    run = tmp_path / "run"
    ev = EvalConfig(iters=3, max_side=24)
    with rf.claimed(run) as r:
        import_poses(SfmConfig(), photos / "transforms.json", r)
        sfm = load_sfm(r)
        cams = eval_cameras(sfm.cameras, ev.max_side)
        paths = image_paths(r, list(sfm.cameras.names), sfm.records)
        old = rf.held_token(r)
        args = (str(r), Unit("selection", "selection", None, [1, 2, 3]), ev, cams, paths, [0, 6],
                default_box(sfm.cameras))
        m = train_unit(*args, "key1", None, old)  # the holder's own worker writes
        assert (r / "evaluate" / "selection" / "stage.json").is_file() and m["n_train"] == 3
    with rf.claimed(run):  # another run took the folder
        with pytest.raises(rf.StaleWorker):
            train_unit(*args[:1], Unit("random_s0", "random", 0, [3, 4, 5]), *args[2:], "key2", None, old)
    assert not (run / "evaluate" / "random_s0" / "stage.json").exists()
    assert not (run / "evaluate" / "random_s0" / "metrics.json").exists()
    with pytest.raises(rf.StaleWorker):  # released, nobody holds it: the worker's run is over
        train_unit(*args[:1], Unit("random_s0", "random", 0, [3, 4, 5]), *args[2:], "key2", None, old)


def test_die_with_parent_ends_a_worker_whose_parent_was_killed(tmp_path):
    """A parent starts a child running die_with_parent, then is SIGKILLed: the child is gone within seconds."""
    child = ("import os, sys, time; from curate.core.runfolder import die_with_parent; "
             "die_with_parent(int(sys.argv[1])); print(os.getpid(), flush=True); time.sleep(60)")
    parent = ("import subprocess, sys, os, time; c = subprocess.Popen([sys.executable, '-c', sys.argv[1], "
              "str(os.getpid())], stdout=subprocess.PIPE, text=True); print(c.stdout.readline().strip(), flush=True); "
              "time.sleep(60)")
    p = subprocess.Popen([sys.executable, "-c", parent, child], env=_env(), stdout=subprocess.PIPE, text=True)
    cpid = int(p.stdout.readline())
    assert rf.pid_alive(cpid)
    p.kill()
    p.wait()
    assert _gone([cpid], 5.0)


# ------------------------------------------------------------------ (3) kill -9: no orphan keeps training
def _children(pid: int) -> list[int]:
    out = []
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
                if int(stat[stat.rindex(")") + 2:].split()[1]) == pid:
                    out.append(int(d.name))
            except (OSError, ValueError):
                pass
    return out


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        kids = _children(todo.pop())
        out += kids
        todo += kids
    return out


def _gone(pids: list[int], timeout: float) -> bool:
    t0 = time.time()
    while time.time() - t0 < timeout:
        alive = [p for p in pids if rf.pid_alive(p) and "zombie" not in _state(p)]
        if not alive:
            return True
        time.sleep(0.1)
    return False


def _state(pid: int) -> str:
    try:
        s = Path(f"/proc/{pid}/status").read_text()
        return next(line for line in s.splitlines() if line.startswith("State:")).lower()
    except (OSError, StopIteration):
        return "gone"


def _is_worker(pid: int) -> bool:
    try:
        cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return False
    return "spawn_main" in cmd and "resource_tracker" not in cmd


def _kill_when_training(cmd: list[str], depth: int, victim: str = "main") -> tuple[subprocess.Popen, list[int]]:
    """Start ``cmd``; once ``depth`` spawned processes exist (1: the run's training worker; 2: a batch
    folder's process and its worker) SIGKILL the command alone (``victim`` 'main') or the folder's
    process alone ('folder'). Returns the command and the descendants of the killed process."""
    p = subprocess.Popen(cmd, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                         start_new_session=True)
    t0 = time.time()
    try:
        while True:
            assert p.poll() is None, "the run ended before its trainings could be caught"
            assert time.time() - t0 < 60, "no training worker appeared"
            desc = _descendants(p.pid)
            workers = [d for d in desc if _is_worker(d)]
            if len(workers) >= depth:
                break
            time.sleep(0.05)
        if victim == "main":
            os.kill(p.pid, signal.SIGKILL)
            p.wait()
            return p, desc
        folder = next(d for d in _children(p.pid) if _is_worker(d))
        desc = _descendants(folder)
        os.kill(folder, signal.SIGKILL)
        return p, desc
    except BaseException:
        os.killpg(p.pid, signal.SIGKILL)
        raise


@pytest.mark.slow
def test_kill_9_of_curate_run_leaves_no_training_worker(tmp_path):
    photos = project(tmp_path / "cap", n=40)
    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "curate", "run", str(photos / "images"), "--poses", str(photos / "transforms.json"),
           "--out", str(run), "--budget", "6", "--iters", "40", "--eval-size", "32", "--res", "8",
           "--random-seeds", "2", "--workers", "2"]
    p, desc = _kill_when_training(cmd, 1)
    try:
        assert _gone(desc, 5.0), [(d, _state(d)) for d in desc if rf.pid_alive(d)]
    finally:
        for d in desc:
            if rf.pid_alive(d):
                os.kill(d, signal.SIGKILL)
    with rf.claimed(run):  # the folder is free again
        pass


@pytest.mark.slow
@pytest.mark.parametrize("victim", ["main", "folder"])
def test_kill_9_of_curate_batch_or_of_a_folder_process_leaves_no_worker(tmp_path, victim):
    photos = project(tmp_path / "cap", n=40)
    runs = tmp_path / "runs"
    cmd = [sys.executable, "-m", "curate", "batch", str(photos), "--out", str(runs), "--budget", "6", "--iters",
           "40", "--eval-size", "32", "--res", "8", "--random-seeds", "2", "--workers", "2", "--jobs", "1"]
    p, desc = _kill_when_training(cmd, 2, victim)  # the folder's process and one of its training workers
    try:
        assert desc and _gone(desc, 5.0), [(d, _state(d)) for d in desc if rf.pid_alive(d)]
        if victim == "folder":  # the batch goes on and reports the folder failed
            out = p.communicate(timeout=60)[0]
            assert p.returncode == 1 and "killed by signal 9" in out, out
    finally:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGKILL)
        for d in desc:
            if rf.pid_alive(d):
                os.kill(d, signal.SIGKILL)


@pytest.mark.slow
def test_two_runs_on_one_out_the_second_is_refused(tmp_path):
    photos = project(tmp_path / "cap", n=30)
    run = tmp_path / "run"
    base = [sys.executable, "-m", "curate", "run", str(photos / "images"), "--poses", str(photos / "transforms.json"),
            "--out", str(run), "--iters", "20", "--eval-size", "32", "--res", "8", "--random-seeds", "1",
            "--workers", "1", "--folds", "2"]
    a = subprocess.Popen(base + ["--budget", "8"], env=_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                         text=True, start_new_session=True)
    try:
        t0 = time.time()
        while rf.read_lock(run).get("pid") != a.pid:
            assert a.poll() is None and time.time() - t0 < 30
            time.sleep(0.05)
        b = subprocess.run(base + ["--budget", "4"], env=_env(), capture_output=True, text=True, timeout=60)
        assert b.returncode == 2
        assert f"is in use by curate run, PID {a.pid}" in b.stderr and "PSNR" not in b.stdout
        assert a.wait(120) == 0
        assert json.loads((run / "select" / "selection.json").read_text())["budget"] == 8
        assert len(list((run / "export" / "images").iterdir())) == 8
    finally:
        if a.poll() is None:
            os.killpg(a.pid, signal.SIGKILL)


def test_a_run_folder_of_curate_0_1_is_refused_with_a_clear_message(tmp_path):
    """A run folder written before the marker existed is refused, not guessed at, and not touched."""
    from curate.core import runfolder
    old = tmp_path / "old"
    (old / "sfm").mkdir(parents=True)
    (old / "run.json").write_text('{"config": {}}')
    (old / "sfm" / "stage.json").write_text('{"key": "x"}')
    before = sorted(p.name for p in old.rglob("*"))
    for adopt in (False, True):
        with pytest.raises(runfolder.RunFolderError, match="curate 0.1.*new folder"):
            runfolder.claim(old, adopt=adopt)
    assert sorted(p.name for p in old.rglob("*")) == before


def test_a_run_folder_of_another_capture_is_not_replaced_without_force(tmp_path, capsys):
    """Issue 49: `--out` given a folder that holds a run of another capture (a typo) redid it for the new input
    and the old run was gone without a word. It is refused, naming what the folder holds; the same capture
    moved elsewhere (the same photo names, the same pose file) resumes; --force replaces the run."""
    import shutil
    from curate.cli import main
    from test_export import ring, write_photos
    from curate.core.transforms_json import write_transforms
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    fast = ["--budget", "4", "--no-evaluate", "--res", "8", "--triangulate", "off", "--refine-iters", "20"]
    run = tmp_path / "run"
    assert main(["run", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--out", str(run),
                 *fast]) == 0
    other = tmp_path / "other"
    cams = ring(12)
    write_photos(other, cams)
    write_transforms(other / "transforms.json", cams)
    stamp = (run / "report.json").read_bytes()
    capsys.readouterr()
    assert main(["run", str(other), "--poses", str(other / "transforms.json"), "--out", str(run), *fast]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert "holds a run of another capture" in err and str(sample / "images") in err and "--force" in err
    assert (run / "report.json").read_bytes() == stamp
    moved = tmp_path / "moved"
    shutil.copytree(sample, moved)
    assert main(["run", str(moved / "images"), "--poses", str(moved / "transforms.json"), "--out", str(run),
                 *fast]) == 0                                      # the same capture, moved: not refused
    assert json.loads((run / "run.json").read_text())["photos"] == str(moved / "images")
    # the same poses with the photos found beside them (no photo folder named) is the same capture too;
    # another pose file without photos is not
    assert main(["run", "--poses", str(moved / "transforms.json"), "--out", str(run), *fast]) == 0
    assert main(["run", "--poses", str(other / "transforms.json"), "--out", str(run), *fast]) == 2
    assert main(["run", str(other), "--poses", str(other / "transforms.json"), "--out", str(run), *fast,
                 "--force"]) == 0
    assert json.loads((run / "run.json").read_text())["photos"] == str(other)


def test_run_json_records_absolute_inputs_so_another_directory_is_the_same_capture(tmp_path, monkeypatch):
    """Relative inputs were recorded as typed: the same capture run again from another directory was refused as
    another one (and a stage re-run looked for the photos in the wrong place)."""
    from curate.cli import main
    from test_export import ring, write_photos
    from curate.core.transforms_json import write_transforms
    cap = tmp_path / "cap"
    write_photos(cap, ring(12))
    write_transforms(cap / "transforms.json", ring(12))
    fast = ["--budget", "4", "--no-evaluate", "--res", "8", "--triangulate", "off", "--method", "medoids"]
    monkeypatch.chdir(tmp_path)
    assert main(["run", "cap", "--poses", "cap/transforms.json", "--out", "run", *fast]) == 0
    rec = json.loads((tmp_path / "run" / "run.json").read_text())
    assert rec["photos"] == str(cap) and rec["poses"] == str(cap / "transforms.json")
    monkeypatch.chdir(cap)
    assert main(["run", ".", "--poses", "transforms.json", "--out", str(tmp_path / "run"), *fast]) == 0


def test_what_a_killed_matching_left_in_the_sfm_folder_is_curates(tmp_path):
    """A run killed (SIGKILL, power loss) while matching in pieces leaves the pieces' folder (``sfm/match_*``)
    and the pair list (``sfm/<matcher>_pairs.txt``): both are curate's, cleared by the next run, not taken for
    the user's files that block it."""
    from curate.cli import main
    sample = Path(__file__).resolve().parents[1] / "data_samples" / "room_walk"
    run = tmp_path / "run"
    argv = ["sfm", str(sample / "images"), "--poses", str(sample / "transforms.json"), "--out", str(run),
            "--triangulate", "off"]
    assert main(argv) == 0
    (run / "sfm" / "match_abc").mkdir()
    (run / "sfm" / "match_abc" / "0.db").write_bytes(b"half a copy")
    (run / "sfm" / "sequential_pairs.txt").write_text("a.jpg b.jpg\n")
    (run / "sfm" / "stage.json").unlink()          # killed before its record: the stage is done again
    assert main(argv) == 0
    assert not (run / "sfm" / "match_abc").exists() and not (run / "sfm" / "sequential_pairs.txt").exists()
